"""fpr_model.numeric_dispatch: the pinned environment, what a process runs, and the restart into it."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from fpr_model.numeric_dispatch import (
    OPENBLAS_CORE,
    REEXEC_MARK,
    _umath,
    numeric_dispatch_in_effect,
    openblas_core,
    pinned_environment,
    reexec_pinned,
)

_SAY = ("import scipy.linalg; from fpr_model.numeric_dispatch import numeric_dispatch_in_effect, openblas_cores; "
        "print(numeric_dispatch_in_effect(), *sorted(set(openblas_cores().values())))")  # numpy's and scipy's


def _clean_environment() -> dict[str, str]:
    return {k: v for k, v in os.environ.items()
            if k not in ("NPY_DISABLE_CPU_FEATURES", "OPENBLAS_CORETYPE", "GLIBC_TUNABLES", REEXEC_MARK)}


def test_the_pinned_environment_replaces_the_three_variables_and_keeps_other_tunables():
    environment = pinned_environment({"PATH": "/bin", "OPENBLAS_CORETYPE": "SkylakeX", "NPY_DISABLE_CPU_FEATURES": "",
                                      "GLIBC_TUNABLES": "glibc.malloc.check=1:glibc.cpu.hwcaps=-AVX2"})
    assert environment["PATH"] == "/bin"
    assert environment["OPENBLAS_CORETYPE"] == OPENBLAS_CORE == "Nehalem"
    assert environment["GLIBC_TUNABLES"] == "glibc.malloc.check=1:glibc.cpu.hwcaps=-FMA,-FMA4"
    assert environment["NPY_DISABLE_CPU_FEATURES"].split() == list(_umath().__cpu_dispatch__)
    assert pinned_environment({})["GLIBC_TUNABLES"] == "glibc.cpu.hwcaps=-FMA,-FMA4"


@pytest.mark.skipif(openblas_core() is None, reason="numpy's OpenBLAS cannot be asked its kernels here")
def test_a_process_started_in_the_pinned_environment_runs_the_pinned_code():
    native = subprocess.run([sys.executable, "-c", _SAY], env=_clean_environment(), capture_output=True, text=True,
                            check=True).stdout.split()
    pinned = subprocess.run([sys.executable, "-c", _SAY], env=pinned_environment(_clean_environment()),
                            capture_output=True, text=True, check=True).stdout.split()
    assert pinned == ["baseline", OPENBLAS_CORE]  # both OpenBLAS took the name (an unknown one falls back to Katmai)
    if native[1:] != [OPENBLAS_CORE]:  # any CPU newer than a Nehalem
        assert native[0] == "native"


def test_the_restart_keeps_the_command_line_and_runs_pinned():
    code = ("import sys; from fpr_model.numeric_dispatch import reexec_pinned, numeric_dispatch_in_effect; "
            "reexec_pinned(); print('after', numeric_dispatch_in_effect(), sys.argv[1:])")
    done = subprocess.run([sys.executable, "-c", code, "table_4_2", "--quick"], env=_clean_environment(),
                          capture_output=True, text=True, check=True)
    lines = done.stdout.strip().splitlines()
    assert lines[-1] == "after baseline ['table_4_2', '--quick']"
    assert len([line for line in lines if "starting again" in line]) <= 1  # at most once, announced


def test_a_restart_that_does_not_pin_stops_with_one_error_instead_of_looping(monkeypatch):
    if numeric_dispatch_in_effect() == "baseline":
        pytest.skip("this test process already runs the pinned code")
    monkeypatch.setenv(REEXEC_MARK, "1")
    with pytest.raises(RuntimeError, match="not in effect after a restart"):
        reexec_pinned()


def test_on_another_architecture_the_restart_says_so_and_runs_on(monkeypatch, capsys):
    import platform

    monkeypatch.setattr(platform, "machine", lambda: "aarch64")
    reexec_pinned()  # returns: nothing to restart
    assert "the pin covers x86-64 CPUs; this one is aarch64" in capsys.readouterr().out
