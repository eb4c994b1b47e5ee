"""cli/arguments.py through the real command-line parser: a bad number is refused by
argparse (exit 2) with the option, the value and the rule, before anything starts; a
good one arrives converted."""

from __future__ import annotations

import pytest

from groundstation.cli.arguments import count, fraction, number
from groundstation.cli.main import build_parser


@pytest.mark.parametrize("argv, message", [
    (["analyze", "x.h5", "--psd-segment", "-3"], "--psd-segment: must be > 0, not -3"),
    (["analyze", "x.h5", "--integration-period", "inf"], "must be > 0, not inf"),
    (["analyze", "x.h5", "--max-excluded-fraction", "1.5"],
     "must be a fraction from 0 to 1, not 1.5"),
    (["analyze", "x.h5", "--from", "soon"], "not a number of seconds: 'soon'"),
    (["analyze", "x.h5", "--to", "nan"], "must be a finite number of seconds, not nan"),
    (["analyze", "x.h5", "--table", "t.csv", "--workers", "0"], "must be >= 1, not 0"),
    (["analyze", "x.h5", "--table", "t.csv", "--workers", "2.5"],
     "not a whole number: '2.5'"),
    (["campaign", "run", "c.toml", "--max-step-seconds", "0"],
     "must be a finite number of seconds > 0, not 0"),
    (["fg", "off", "--resource", "sim", "--timeout", "0.0001"],
     "must be at least 0.001, not 0.0001"),
    (["sim", "--speed", "0"], "--speed: must be > 0, not 0"),
])
def test_a_bad_number_is_refused_with_its_rule(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_:
        build_parser().parse_args(argv)
    assert exit_.value.code == 2
    assert message in capsys.readouterr().err


def test_good_values_arrive_converted():
    args = build_parser().parse_args(["analyze", "x.h5", "--psd-segment", "2.5",
                                      "--max-excluded-fraction", "0", "--from", "-1"])
    assert (args.psd_segment, args.max_excluded_fraction, args.start) == (2.5, 0.0, -1.0)
    assert count("3") == 3 and fraction("1") == 1.0


def test_a_rule_of_ones_own():
    odd = number(lambda v: v % 2 == 1, "must be odd", convert=int, what="a whole number")
    assert odd("7") == 7
    with pytest.raises(Exception, match="must be odd, not 4"):
        odd("4")
