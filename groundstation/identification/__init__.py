"""The twin of a lab's own rig: the testbed's parameters identified from its logs.

`pipeline.identify` sorts the logs by what their profiles drove, turns the open-loop
ones into measured frequency responses and fits the plant to them
(analysis.plant_fit), identifies the bearing's friction from the position-profile ones
(`friction`), measures the plant fit's bias on a twin of the result and takes it out
(`twin_bias`), and says what each parameter came from; `testbed_file.write_identified`
writes the result as a testbed file (and its slope table) that the simulator,
validation, the design workbench and the analysis load unchanged; `report` puts the
figures in words and JSON, `curves` gives the measured and model responses as arrays,
`figures` and `html` draw them into PNGs and one self-contained page.
`groundstation identify` is the command; the window's Analysis dock has Identify.
"""
