"""The twin of a lab's own rig: the testbed's parameters identified from its logs.

`pipeline.identify` turns open-loop identification logs into measured frequency
responses, fits the plant to them (analysis.plant_fit) and says what each parameter
came from; `testbed_file.write_identified` writes the result as a testbed file the
simulator, validation, the design workbench and the analysis load unchanged;
`report` puts the figures in words and JSON.  `groundstation identify` is the command.
"""
