"""OpenCV's CPU dispatch, for image pipelines whose results do not depend on the machine (issue 15).

OpenCV chooses SIMD code at run time from the CPU's features (``cv::checkHardwareSupport``: the opencv-python
wheel is built with an SSE3 baseline and dispatched SSE4.1 / AVX / AVX2 / AVX-512 variants) and may call Intel
IPP, which dispatches on its own. The variants round differently, so a seeded simulation with rendered images
and ArUco detection flies a slightly different flight on another CPU. Measured 2026-12-06 (docs/results.md,
table_4_6, 100 s, AMD EPYC with AVX-512): the same commit and seed gave a platform roll RMSE of 3.42° on the
previous session's VM and 3.36° here; here, ``OPENCV_CPU_DISABLE=AVX2,FMA3,AVX512F,AVX512-SKX`` (a CPU without
AVX2) gave 3.364° against 3.362°, and every metric moved in the third or fourth digit. Flights with emulated
marker poses (no OpenCV in the loop) were bit-identical across both VMs.

``baseline`` runs ``cv2.setUseOptimized(False)``: every dispatched variant, IPP and OpenCL off, so every x86_64
CPU runs the wheel's own baseline code and the same pinned wheel gives the same images and detections. It is a
process-wide OpenCV switch, not a node's, hence an environment variable (:data:`ENVIRONMENT_VARIABLE`, inherited
by the processes of a multi-process graph) read by the nodes that use OpenCV (``fpr_sim`` simulator,
``fpr_estimation`` aruco_detector) when they start. ``native`` (the default, what the robot runs) leaves OpenCV's
own choice. The experiments runner (fpr_experiments) flies in ``baseline`` unless told otherwise.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping
from contextlib import contextmanager

#: environment variable naming the dispatch mode of the process (and of the processes it starts)
ENVIRONMENT_VARIABLE = "FPR_OPENCV_DISPATCH"
#: ``native``: OpenCV's own choice (the default); ``baseline``: cv2.setUseOptimized(False)
MODES = ("native", "baseline")


def opencv_dispatch_mode(environ: Mapping[str, str] | None = None) -> str:
    """The mode :data:`ENVIRONMENT_VARIABLE` asks for (``native`` when unset or empty); ValueError naming the
    variable and the valid modes for anything else."""
    value = (os.environ if environ is None else environ).get(ENVIRONMENT_VARIABLE, "").strip().lower()
    if not value:
        return "native"
    if value not in MODES:
        raise ValueError(f"{ENVIRONMENT_VARIABLE}={value!r}: expected one of {', '.join(MODES)}")
    return value


def apply_opencv_dispatch(mode: str | None = None) -> str:
    """Set OpenCV's dispatch for this process to ``mode`` (None: :func:`opencv_dispatch_mode`); returns it."""
    import cv2

    mode = opencv_dispatch_mode() if mode is None else mode
    if mode not in MODES:
        raise ValueError(f"OpenCV dispatch {mode!r}: expected one of {', '.join(MODES)}")
    cv2.setUseOptimized(mode == "native")
    return mode


@contextmanager
def opencv_dispatch(mode: str) -> Iterator[str]:
    """Run a block (and the processes it starts) in ``mode``; this process's OpenCV switch and the environment
    variable are restored afterwards."""
    import cv2

    if mode not in MODES:
        raise ValueError(f"OpenCV dispatch {mode!r}: expected one of {', '.join(MODES)}")
    previous_variable = os.environ.get(ENVIRONMENT_VARIABLE)
    previous_optimized = cv2.useOptimized()
    os.environ[ENVIRONMENT_VARIABLE] = mode
    try:
        yield apply_opencv_dispatch(mode)
    finally:
        if previous_variable is None:
            os.environ.pop(ENVIRONMENT_VARIABLE, None)
        else:
            os.environ[ENVIRONMENT_VARIABLE] = previous_variable
        cv2.setUseOptimized(previous_optimized)
