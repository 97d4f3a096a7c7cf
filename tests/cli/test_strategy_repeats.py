"""``--strategy-repeats N`` (harness run, harness report --studies): the strategy table's independent seeds per
budget, 2 to 100 (an interval needs two), refused otherwise in one line naming the option (exit 2), and carried to
the studies' options. Nothing renders here."""

from __future__ import annotations

import pytest

from harness.cli import build_parser, main
from harness.cli.study_compute import study_options
import harness.cli.studies as cli_studies
from harness.studies.strategies import STRATEGY_REPEATS


def test_strategy_repeats_reach_the_studies_options():
    args = build_parser("run").parse_args(["run", "suites/smoke.toml", "--strategy-repeats", "7"])
    assert study_options(args).strategy_repeats == 7
    args = build_parser("run").parse_args(["run", "suites/smoke.toml"])
    assert study_options(args).strategy_repeats == cli_studies.DEFAULT_STRATEGY_REPEATS == STRATEGY_REPEATS
    args = build_parser("report").parse_args(["report", "results.json", "--studies", "--strategy-repeats", "2"])
    assert study_options(args).strategy_repeats == 2


@pytest.mark.parametrize("argv", [["run", "suites/smoke.toml", "--strategy-repeats", "1"],
                                  ["run", "suites/smoke.toml", "--strategy-repeats", "101"],
                                  ["run", "suites/smoke.toml", "--strategy-repeats", "four"],
                                  ["report", "results.json", "--studies", "--strategy-repeats", "0"],
                                  ["report", "results.json", "--strategy-repeats", "3"]])
def test_bad_strategy_repeats_are_one_line_naming_the_option(argv, capfd):
    code = main(argv + ["--quiet"])
    err = capfd.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--strategy-repeats" in err, err
