"""``run``'s numeric pin (fpr_model.numeric_dispatch) when run_main is called inside another Python process."""

from __future__ import annotations

import pytest
from fpr_experiments.cli import _experiment_flags, _parser, pin_numeric_code

from fpr_model import numeric_dispatch


@pytest.fixture
def native_process(monkeypatch):
    """This process as an unpinned one, whatever the test runner's environment (pin_numeric_code asks
    fpr_model.numeric_dispatch at call time)."""
    monkeypatch.setattr(numeric_dispatch, "numeric_dispatch_in_effect", lambda: "native")


def test_in_another_process_the_pin_says_what_runs_and_does_not_restart_it(native_process, capsys):
    pin_numeric_code("baseline", entry_point=False)  # would replace pytest's process if it restarted
    assert "numeric code: native in this process" in capsys.readouterr().out
    pin_numeric_code("native", entry_point=True)  # native: nothing to pin, nothing said
    assert capsys.readouterr().out == ""


def test_cpu_dispatch_takes_its_former_name_and_goes_to_each_experiment_of_run_all():
    assert _parser().parse_args(["all"]).cpu_dispatch == "baseline"
    args = _parser().parse_args(["all", "--opencv-dispatch", "native"])
    assert args.cpu_dispatch == "native"
    assert _experiment_flags(args)[-2:] == ["--cpu-dispatch", "native"]
    with pytest.raises(SystemExit):
        _parser().parse_args(["all", "--cpu-dispatch", "avx2"])


def test_as_the_program_on_another_architecture_it_says_one_line_and_flies(native_process, monkeypatch, capsys):
    import platform

    monkeypatch.setattr(platform, "machine", lambda: "aarch64")
    pin_numeric_code("baseline", entry_point=True)  # no restart on aarch64: the pin is x86-64's
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 1 and "this one is aarch64" in lines[0]
