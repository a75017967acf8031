"""The numeric libraries' CPU dispatch, for simulations whose results do not depend on the machine (issue 15).

Three libraries below the project's own code pick their code from the CPU's features when they load, and the
variants round differently, so the same commit and seed flew a different flight on another x86-64 CPU, even with
emulated marker poses and OpenCV pinned (:mod:`fpr_model.opencv_dispatch`). Measured 2026-12-07 on an Intel Xeon
with AVX-512 (quick table_4_2 C flight, 16 s, emulated cameras): each of the following alone, as a CPU without
the feature would see it, changed every metric from the ninth digit on (e.g. the roll RMSE 3.287330578° →
3.287330526°):

- **numpy** dispatches its ufunc loops (``X86_V3`` = AVX2/FMA3, ``X86_V4`` and the AVX-512 groups: sin, cos, exp,
  log and reductions among them) on top of its build's baseline (``X86_V2`` for numpy 2.4). The environment
  variable ``NPY_DISABLE_CPU_FEATURES``, read when numpy is imported, turns the dispatched groups off.
- **OpenBLAS** (numpy's and scipy's: matrix products, ``pinv``, ``solve``) picks its kernels by CPU model
  (``SkylakeX`` here, ``Haswell`` on an AVX2 machine). ``OPENBLAS_CORETYPE``, read when the library loads, pins
  one. Pinned here: ``Nehalem``, the oldest kernel set of the wheels' build that every CPU numpy 2.4 runs on has
  (SSE4.2, numpy's own baseline; a name the build lacks falls back to ``Katmai`` silently, hence the check below).
- **glibc's libm** (Python's ``math``, numpy's scalar and libm-backed loops, the compiled plant kernel) selects
  FMA variants of sin, cos, exp, log, pow, atan2 … on CPUs with FMA (ifuncs); they round differently from the
  SSE2 variants in a few ulp of some arguments. ``GLIBC_TUNABLES=glibc.cpu.hwcaps=-FMA,-FMA4`` hides FMA from
  glibc's selection (every non-FMA variant gives the same bits: checked with AVX, AVX2, SSE4 hidden as well).

All three are read once, at process start, so they cannot be switched in a running process as OpenCV can: a
program that wants the pinned code starts itself again with :func:`pinned_environment` (:func:`reexec_pinned`).
Its child processes inherit the environment. x86-64 only: on another architecture (aarch64) :func:`reexec_pinned`
says so in one line and runs on, ``native``. numpy 1.26 (Ubuntu 24.04's, a real Jazzy install) and a distribution's
libopenblas are asked the same way as the wheels. The robot's nodes run ``native``, as they are started.
The speed cost, measured on the whole graph: docs/benchmarks.md.
"""

from __future__ import annotations

import ctypes
import os
import platform
import sys
from collections.abc import Mapping

#: marks a process started again by :func:`reexec_pinned` (a second attempt that still is not pinned stops)
REEXEC_MARK = "FPR_NUMERIC_DISPATCH_REEXEC"
#: the OpenBLAS kernel set every CPU numpy 2.4 runs on has (SSE4.2)
OPENBLAS_CORE = "Nehalem"
#: glibc's CPU features hidden from its function selection (libm's FMA variants)
GLIBC_HIDDEN = "-FMA,-FMA4"
_HWCAPS = "glibc.cpu.hwcaps"


def _umath():
    """numpy's compiled core (``numpy._core`` from numpy 2, ``numpy.core`` in the numpy 1.26 of Ubuntu 24.04)."""
    try:
        from numpy._core import _multiarray_umath
    except ImportError:  # numpy < 2
        from numpy.core import _multiarray_umath
    return _multiarray_umath


def _numpy_dispatched_groups() -> list[str]:
    """The CPU feature groups this numpy build dispatches on (build-time list: the same on every machine; a group
    the machine lacks is skipped by numpy with a silent ImportWarning)."""
    return list(_umath().__cpu_dispatch__)


def _merged_tunables(current: str) -> str:
    """``GLIBC_TUNABLES`` with this module's hwcaps entry in place of any hwcaps entry there was."""
    kept = [entry for entry in current.split(":") if entry and not entry.startswith(_HWCAPS + "=")]
    return ":".join([*kept, f"{_HWCAPS}={GLIBC_HIDDEN}"])


def pinned_environment(environ: Mapping[str, str] | None = None) -> dict[str, str]:
    """A copy of ``environ`` (default: this process's) in which numpy, OpenBLAS and libm run the pinned code.

    Values already there for the three variables are replaced, not merged (a machine's own setting is what the pin
    is for), except ``GLIBC_TUNABLES``' other tunables, which are kept."""
    environment = dict(os.environ if environ is None else environ)
    environment["NPY_DISABLE_CPU_FEATURES"] = " ".join(_numpy_dispatched_groups())
    environment["OPENBLAS_CORETYPE"] = OPENBLAS_CORE
    environment["GLIBC_TUNABLES"] = _merged_tunables(environment.get("GLIBC_TUNABLES", ""))
    return environment


_CORENAME_SYMBOLS = ("scipy_openblas_get_corename64_", "scipy_openblas_get_corename", "openblas_get_corename64_",
                     "openblas_get_corename")


def _loaded_openblas_libraries() -> list[str]:
    """Paths of the OpenBLAS libraries mapped into this process (numpy's and, once imported, scipy's wheels' copies,
    or a distribution's libopenblas)."""
    try:
        with open("/proc/self/maps", encoding="utf-8") as maps:
            paths = {line.split()[-1] for line in maps if "openblas" in line.rsplit("/", 1)[-1].lower()}
    except OSError:
        return []
    return sorted(path for path in paths if path.startswith("/"))


def openblas_cores() -> dict[str, str]:
    """The kernel set (``SkylakeX``, ``Nehalem`` …) of every OpenBLAS loaded in this process that can be asked, by
    library path; numpy (and its BLAS) imported first."""
    import numpy  # noqa: F401  (loads numpy's BLAS)

    cores = {}
    for path in _loaded_openblas_libraries():
        try:
            library = ctypes.CDLL(path)
        except OSError:
            continue
        for symbol in _CORENAME_SYMBOLS:
            if hasattr(library, symbol):
                function = getattr(library, symbol)
                function.restype = ctypes.c_char_p
                cores[path] = function().decode()
                break
    return cores


def openblas_core() -> str | None:
    """The kernel set of numpy's OpenBLAS (the first loaded that can be asked); None when none can (another BLAS,
    not Linux)."""
    return next(iter(openblas_cores().values()), None)


def numeric_dispatch_in_effect() -> str:
    """``baseline`` when this process runs the pinned code (numpy's dispatched groups all off, OpenBLAS on the
    pinned kernels, libm's FMA hidden), ``native`` otherwise."""
    features = _umath().__cpu_features__
    numpy_pinned = not any(features.get(group, False) for group in _numpy_dispatched_groups())
    cores = set(openblas_cores().values())
    blas_pinned = cores == {OPENBLAS_CORE} or (not cores and os.environ.get("OPENBLAS_CORETYPE") == OPENBLAS_CORE)
    libm_pinned = f"{_HWCAPS}={GLIBC_HIDDEN}" in os.environ.get("GLIBC_TUNABLES", "").split(":")
    return "baseline" if numpy_pinned and blas_pinned and libm_pinned else "native"


def reexec_pinned(argv: list[str] | None = None) -> None:
    """Start this program again, same arguments, in :func:`pinned_environment`, unless it already runs pinned.

    ``argv``: the command line to run again (default ``sys.orig_argv``, the interpreter's own, ``-c`` / ``-m``
    included). Returns only when nothing needs doing. RuntimeError when a process already started again still is
    not pinned (a library the pin does not cover): rather one clear error than a loop. On a CPU that is not x86-64
    it says in one line that the code stays native, and returns."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        print(f"[fpr] numeric code: native (the pin covers x86-64 CPUs; this one is {platform.machine()}), so a "
              f"flight here may differ in its last digits from the same flight on another CPU", flush=True)
        return
    if numeric_dispatch_in_effect() == "baseline":
        return
    if os.environ.get(REEXEC_MARK):
        raise RuntimeError(f"the numeric libraries' pinned code is not in effect after a restart in the pinned "
                           f"environment (OpenBLAS {openblas_cores()}, numpy groups {_numpy_dispatched_groups()}): fly "
                           f"with --cpu-dispatch native on this machine")
    command = list(sys.orig_argv if argv is None else argv)
    environment = pinned_environment()
    environment[REEXEC_MARK] = "1"
    print("[fpr] numeric code: starting again with numpy, OpenBLAS and libm pinned to the same code on every CPU "
          "(fpr_model.numeric_dispatch)", flush=True)
    sys.stdout.flush()
    sys.stderr.flush()
    os.execve(sys.executable, [sys.executable, *command[1:]], environment)
