"""fpr_model.opencv_dispatch: the mode from the environment, OpenCV's switch, and its restoration."""

from __future__ import annotations

import os

import cv2
import pytest
from fpr_model.opencv_dispatch import (
    ENVIRONMENT_VARIABLE,
    apply_opencv_dispatch,
    opencv_dispatch,
    opencv_dispatch_mode,
)


def test_mode_from_the_environment():
    assert opencv_dispatch_mode({}) == "native"
    assert opencv_dispatch_mode({ENVIRONMENT_VARIABLE: ""}) == "native"
    assert opencv_dispatch_mode({ENVIRONMENT_VARIABLE: " Baseline "}) == "baseline"
    with pytest.raises(ValueError, match="FPR_OPENCV_DISPATCH='fast': expected one of native, baseline"):
        opencv_dispatch_mode({ENVIRONMENT_VARIABLE: "fast"})


def test_apply_switches_opencv_and_the_context_restores_it(monkeypatch):
    monkeypatch.delenv(ENVIRONMENT_VARIABLE, raising=False)
    cv2.setUseOptimized(True)
    try:
        with opencv_dispatch("baseline") as mode:
            assert mode == "baseline" and not cv2.useOptimized()
            assert os.environ[ENVIRONMENT_VARIABLE] == "baseline"  # the processes it starts fly baseline too
            assert apply_opencv_dispatch() == "baseline"  # what a node started here applies
        assert cv2.useOptimized() and ENVIRONMENT_VARIABLE not in os.environ
        monkeypatch.setenv(ENVIRONMENT_VARIABLE, "baseline")
        with opencv_dispatch("native"):
            assert cv2.useOptimized()
        assert os.environ[ENVIRONMENT_VARIABLE] == "baseline"
        assert apply_opencv_dispatch() == "baseline" and not cv2.useOptimized()
        assert apply_opencv_dispatch("native") == "native" and cv2.useOptimized()
        with pytest.raises(ValueError, match="expected one of"):
            apply_opencv_dispatch("avx2")
        with pytest.raises(ValueError, match="expected one of"), opencv_dispatch("avx2"):
            pass
    finally:
        cv2.setUseOptimized(True)
