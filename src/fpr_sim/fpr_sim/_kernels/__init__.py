"""Optional compiled kernel of the 1 kHz plant (plant_kernel.c, plain C99 loaded with ctypes) and its selection.

The same library also finishes rendered camera frames (:class:`FrameKernel`, for fpr_sim.camera_renderer): the
photometric table, lighting gradient and sensor noise in one pass, bit for bit the renderer's numpy/OpenCV path.

The Python implementation (fpr_sim.plant / structure / quadrotor) is the reference and the fallback; the C file
is a line-by-line port of it (same equations, same order of operations where practical) and gets every model
constant from Python: the fitted mass-matrix basis of :class:`~fpr_sim.structure.StructureDynamics` (from
fpr_model), the geometry, masses, gains and the scenario's contact / drag constants.

Selection, per object (``kernel=`` of Plant, QuadrotorFleet, StructureDynamics) or process-wide with the
environment variable ``FPR_SIM_KERNEL``:

- ``auto`` (default): the compiled kernel when it is built and loads, else Python (one INFO log line says why);
- ``compiled``: the compiled kernel, RuntimeError if it is not available;
- ``python``: the pure-Python reference.

The library is built by ``setup.py`` (an optional extension: colcon build / ``setup.py develop`` compile it when
a C compiler exists and carry on without it otherwise) as ``_fpr_plant_kernel<EXT_SUFFIX>`` next to this file.
A library whose embedded source hash differs from plant_kernel.c next to it (the C file was edited after the
build) is refused as stale (WARNING) rather than silently run.
"""

from __future__ import annotations

import ctypes
import hashlib
import importlib.machinery
import logging
import os
import shutil
import sys
import sysconfig
from dataclasses import dataclass
from functools import lru_cache
from itertools import chain
from pathlib import Path

import numpy as np

__all__ = ["KERNEL_CHOICES", "KERNEL_ENV", "FrameKernel", "KernelStatus", "PlantKernel", "QuadKernel",
           "StructureKernel",
           "compiler_available", "kernel_status", "kernel_summary", "resolve_kernel"]

KERNEL_ENV = "FPR_SIM_KERNEL"
KERNEL_CHOICES = ("auto", "compiled", "python")
#: must equal FPR_KERNEL_ABI in plant_kernel.c
_ABI = 6
_LIBRARY_STEM = "_fpr_plant_kernel"
_SOURCE = Path(__file__).with_name("plant_kernel.c")
_LOG = logging.getLogger("fpr_sim.kernels")

# error codes of plant_kernel.c
_OK = 0
# layout kinds and slot names (enums of plant_kernel.c, in order)
_LAYOUTS = {
    0: ("x", "quat", "rate", "rotors", "rotor_commands", "charge", "tip_velocity", "yaw_anchors", "wind",
        "platform_force", "platform_moment", "rotor_factors", "uav_forces", "current", "tip_position",
        "tip_acceleration", "contact", "ground_active", "size"),
    1: ("quat", "rate", "previous", "integral", "command_quat", "thrust", "armed", "landed", "feedforward",
        "f_max", "setpoint", "integral_out", "commands", "size"),
    2: ("quat", "rate", "rotors", "rotor_commands", "moments", "charge", "rotor_factors", "current", "size"),
    3: ("cos", "sin", "xi", "gravity", "force", "out", "size"),
}
_PLANT, _CONTROL, _QUAD, _ACCELERATE = 0, 1, 2, 3
_FLAG_IDEAL = 1
_FLAG_WIND = 2
_FLAG_FACTORS = 4  #: the realism's per-rotor thrust factors are given (fpr_sim.plant_realism)
_FLAG_UAV_FORCE = 8  #: a held world force on each quadrotor is given (rotor drag)


class FprQuadModel(ctypes.Structure):
    """Mirror of ``FprQuadModel`` in plant_kernel.c (the sizes are checked at load time)."""

    _fields_ = [("n", ctypes.c_int), ("inertia", ctypes.c_double * 3), ("arm", ctypes.c_double),
                ("kappa", ctypes.c_double), ("motor_tau", ctypes.c_double),
                ("attitude_p", ctypes.c_double * 3), ("rate_p", ctypes.c_double * 3),
                ("rate_i", ctypes.c_double * 3), ("rate_d", ctypes.c_double * 3), ("max_rate", ctypes.c_double * 3),
                ("integrator_limit", ctypes.c_double), ("controller_period", ctypes.c_double),
                ("current_per_newton", ctypes.c_double)]


def _plant_model_type(max_n: int) -> type[ctypes.Structure]:
    vec = ctypes.c_double * 3
    per_leg = ctypes.c_double * max_n

    class FprPlantModel(ctypes.Structure):
        """Mirror of ``FprPlantModel`` in plant_kernel.c."""

        _fields_ = [("n", ctypes.c_int), ("leg_length", ctypes.c_double), ("anchors", vec * max_n),
                    ("cos_alpha", per_leg), ("sin_alpha", per_leg), ("joint_axes", vec * max_n),
                    ("gravity", vec), ("gravity_magnitude", ctypes.c_double), ("uav_masses", per_leg),
                    ("joint_offset", vec), ("ground_enabled", ctypes.c_int), ("ground_height", ctypes.c_double),
                    ("ground_stiffness", ctypes.c_double), ("ground_damping", ctypes.c_double),
                    ("ground_tangential_stiffness", ctypes.c_double),
                    ("ground_tangential_damping", ctypes.c_double), ("ground_friction", ctypes.c_double),
                    ("gear_height", ctypes.c_double), ("gear_radius", ctypes.c_double),
                    ("uav_drag", ctypes.c_double), ("leg_drag", ctypes.c_double),
                    ("platform_drag", ctypes.c_double), ("board_enabled", ctypes.c_int),
                    ("board_normal", vec), ("board_point", vec), ("board_stiffness", ctypes.c_double),
                    ("board_damping", ctypes.c_double), ("board_friction", ctypes.c_double),
                    ("board_u", vec), ("board_v", vec), ("board_half_size", ctypes.c_double * 2),
                    ("board_contact_depth", ctypes.c_double),
                    ("end_effector", vec), ("joint_stops_enabled", ctypes.c_int),
                    ("joint_stop_lower", ctypes.c_double), ("joint_stop_upper", ctypes.c_double),
                    ("joint_stop_stiffness", ctypes.c_double), ("joint_stop_damping", ctypes.c_double),
                    ("quad", FprQuadModel)]

    return FprPlantModel


@dataclass(frozen=True)
class KernelStatus:
    """Whether the compiled kernel can be used: ``available``; ``path`` of the library (or None); ``reason``
    (why not, or a one-line description of the loaded library)."""

    available: bool
    path: str | None
    reason: str


class _Library:
    """The loaded shared library with its declared functions and layouts."""

    def __init__(self, path: Path) -> None:
        lib = ctypes.CDLL(str(path))
        self.path = path
        self.max_legs = int(lib.fpr_kernel_max_legs())
        self.plant_model_type = _plant_model_type(self.max_legs)
        lib.fpr_kernel_struct_size.argtypes = [ctypes.c_int]
        sizes = (lib.fpr_kernel_struct_size(0), lib.fpr_kernel_struct_size(1))
        expected = (ctypes.sizeof(FprQuadModel), ctypes.sizeof(self.plant_model_type))
        if sizes != expected:
            raise OSError(f"struct sizes {sizes} != ctypes mirrors {expected}")
        lib.fpr_layout.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_void_p]
        pointer = ctypes.c_void_p
        lib.fpr_plant_step.argtypes = [pointer, pointer, pointer, pointer, ctypes.c_double, ctypes.c_int]
        lib.fpr_quad_control.argtypes = [pointer, pointer, ctypes.c_int]
        lib.fpr_quad_step.argtypes = [pointer, pointer, ctypes.c_double, ctypes.c_int]
        lib.fpr_structure_accelerate.argtypes = [ctypes.c_int, pointer, pointer]
        lib.fpr_frame_finish.argtypes = [ctypes.c_int, ctypes.c_int, pointer, pointer, pointer, pointer, pointer,
                                         ctypes.c_int]
        for function in (lib.fpr_plant_step, lib.fpr_quad_control, lib.fpr_quad_step, lib.fpr_structure_accelerate,
                         lib.fpr_frame_finish):
            function.restype = ctypes.c_int
        self.lib = lib

    def layout(self, kind: int, n: int) -> dict[str, int]:
        """Slot offsets (doubles) of a call's buffer for n legs, from the library itself."""
        names = _LAYOUTS[kind]
        offsets = (ctypes.c_int * len(names))()
        count = self.lib.fpr_layout(kind, n, ctypes.addressof(offsets))
        if count != len(names):
            raise OSError(f"layout {kind}: {count} slots, expected {len(names)}")
        return dict(zip(names, offsets, strict=True))


def _library_path() -> Path | None:
    here = Path(__file__).parent
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        candidate = here / f"{_LIBRARY_STEM}{suffix}"
        if candidate.is_file():
            return candidate
    return None


@lru_cache(maxsize=1)
def _load() -> tuple[_Library | None, KernelStatus]:
    path = _library_path()
    if path is None:
        return None, KernelStatus(False, None, "the compiled plant kernel is not built (no C compiler at build "
                                               "time, or the package was not built with setup.py/colcon)")
    try:
        library = _Library(path)
        abi = int(library.lib.fpr_kernel_abi())
        if abi != _ABI:
            raise OSError(f"ABI {abi}, the loader expects {_ABI}")
        library.lib.fpr_kernel_source_hash.restype = ctypes.c_char_p
        built_from = library.lib.fpr_kernel_source_hash().decode()
        if _SOURCE.is_file() and built_from != "unknown":
            current = hashlib.sha256(_SOURCE.read_bytes()).hexdigest()
            if current != built_from:
                _LOG.warning("fpr_sim: compiled plant kernel %s is stale (plant_kernel.c changed since it was "
                             "built): not used; rebuild (colcon build)", path)
                return None, KernelStatus(False, str(path), "stale build: plant_kernel.c changed since the build")
    except (OSError, AttributeError) as error:
        return None, KernelStatus(False, str(path), f"cannot load {path.name}: {error}")
    return library, KernelStatus(True, str(path), f"compiled plant kernel {path.name}")


def compiler_available() -> bool:
    """A C compiler is on PATH (the interpreter's configured CC, cc, gcc or clang): the kernel should be built."""
    configured = (sysconfig.get_config_var("CC") or "").split()
    names = configured[:1] + ["cc", "gcc", "clang"]
    return any(shutil.which(name) for name in names)


def kernel_status() -> KernelStatus:
    """Whether the compiled kernel is available in this process (loaded once, cached)."""
    return _load()[1]


def kernel_summary(selected: str) -> str:
    """One line for a start-up log: the plant kernel that runs (``selected``: 'compiled' or 'python', e.g.
    ``Plant.kernel``) and why (the library loaded, ``$FPR_SIM_KERNEL``, or why the compiled one is missing)."""
    requested = os.environ.get(KERNEL_ENV, "auto").strip().lower() or "auto"
    status = kernel_status()
    if selected == "compiled":
        return f"compiled ({status.reason}, ${KERNEL_ENV}={requested})"
    if requested == "python":
        return f"python (${KERNEL_ENV}=python)"
    if status.available:
        return "python (the robot has more legs than the compiled kernel's arrays)"
    return f"python ({status.reason})"


_announced = False


def resolve_kernel(choice: str | None = None, n: int | None = None) -> str:
    """'compiled' or 'python' for a requested ``choice`` (None: ``$FPR_SIM_KERNEL``, default 'auto') and a robot
    of ``n`` legs / vehicles (the kernel has a fixed maximum).

    Raises ValueError for an unknown choice and RuntimeError for 'compiled' when the kernel is unavailable.
    With 'auto' and no kernel, logs once per process (INFO) that the pure-Python plant is used and why."""
    global _announced
    if choice is None:
        choice = os.environ.get(KERNEL_ENV, "auto").strip().lower() or "auto"
    if choice not in KERNEL_CHOICES:
        raise ValueError(f"fpr_sim kernel {choice!r} unknown: valid choices are {', '.join(KERNEL_CHOICES)} "
                         f"(argument kernel= or ${KERNEL_ENV})")
    if choice == "python":
        return "python"
    library, status = _load()
    reason = status.reason
    if library is not None:
        if n is None or n <= library.max_legs:
            return "compiled"
        reason = f"n = {n} exceeds the compiled kernel's {library.max_legs}"
    if choice == "compiled":
        raise RuntimeError(f"fpr_sim compiled kernel requested but unavailable: {reason}")
    if not _announced:
        _announced = True
        _info(f"fpr_sim: using the pure-Python plant ({reason})")
    return "python"


def _info(message: str) -> None:
    """One INFO line through ``logging`` when the process configured it, else on stderr (a bare process, e.g.
    the rclpy simulator node, has no logging handler and would drop INFO)."""
    if _LOG.hasHandlers():
        _LOG.info(message)
    else:
        print(f"[INFO] [fpr_sim.kernels]: {message}", file=sys.stderr)


def _library() -> _Library:
    library, status = _load()
    if library is None:
        raise RuntimeError(f"fpr_sim compiled kernel unavailable: {status.reason}")
    return library


def _fill(target, values) -> None:
    for k, v in enumerate(values):
        target[k] = float(v)


def _quad_model(fleet) -> FprQuadModel:
    """The constants of a QuadrotorFleet (and its Battery) for the kernel."""
    model = FprQuadModel()
    model.n = fleet.n
    _fill(model.inertia, fleet.inertia.tolist())
    model.arm, model.kappa, model.motor_tau = fleet.arm, fleet.kappa, fleet.motor_tau
    for name, values in (("attitude_p", fleet.attitude_p), ("rate_p", fleet.rate_p), ("rate_i", fleet.rate_i),
                         ("rate_d", fleet.rate_d), ("max_rate", fleet.max_rate)):
        _fill(getattr(model, name), np.broadcast_to(np.asarray(values, dtype=float), (3,)).tolist())
    model.integrator_limit = fleet.integrator_limit
    model.controller_period = fleet.controller_period
    model.current_per_newton = float(fleet.battery.config.current_per_newton)
    return model


def _pointer(array: np.ndarray, shape: tuple[int, ...]) -> int:
    """Address of a numpy array the kernel reads or writes in place (checked: shape, float64, C order)."""
    if (not isinstance(array, np.ndarray) or array.shape != shape or array.dtype != np.float64
            or not array.flags.c_contiguous or not array.flags.writeable):
        raise ValueError(f"kernel buffer: expected a writeable C-contiguous float64 array of shape {shape}")
    return array.ctypes.data


class StructureKernel:
    """:meth:`StructureDynamics.accelerate` in C for one StructureDynamics (the basis is read at each call)."""

    def __init__(self, structure) -> None:
        library = _library()
        if structure.n > library.max_legs:
            raise RuntimeError(f"n = {structure.n} > {library.max_legs} legs of the compiled kernel")
        self._function = library.lib.fpr_structure_accelerate
        self._layout = library.layout(_ACCELERATE, structure.n)
        self._io = np.zeros(self._layout["size"])
        self._io_pointer = self._io.ctypes.data
        self._out = slice(self._layout["out"], self._layout["size"])
        self._basis = None
        self._basis_pointer = 0

    def accelerate(self, structure, c, s, xi, g_body, q_force) -> list[float] | None:
        """ξ̇ (list) or None when the kernel refuses (singular M̃: the caller runs the Python reference)."""
        io = self._io
        io[:self._layout["out"]] = list(chain(c, s, xi, g_body, q_force))
        n = structure.n
        basis = structure._basis
        if basis is not self._basis:  # a new basis after a payload change
            self._basis_pointer = _pointer(basis, (1 + 4 * n, (6 + n) ** 2))
            self._basis = basis
        status = self._function(n, self._basis_pointer, self._io_pointer)
        if status != _OK:
            return None
        return io[self._out].tolist()


def _float32_address(array: np.ndarray | None, length: int) -> int | None:
    """Address of a C-contiguous float32 vector of ``length`` (None for None)."""
    if array is None:
        return None
    if array.dtype != np.float32 or array.shape != (length,) or not array.flags.c_contiguous:
        raise ValueError(f"frame kernel: expected a C-contiguous float32 vector of {length}, got {array.dtype} "
                         f"{array.shape}")
    return array.ctypes.data


class FrameKernel:
    """The last pass of :meth:`fpr_sim.camera_renderer.MarkerRenderer.render` in C (``fpr_frame_finish``): in
    place on a (height, width) uint8 frame ``I``, ``p = table[I]`` (float32 (256,); None: ``float32(I)``),
    ``p += row_terms[v] + column_terms[u]`` (float32 (height,), (width,); None: no gradient), ``p += noise[v, u]``
    (a float32 (height, width) window with unit column stride, e.g. of a larger bank; None: no noise), then
    OpenCV's saturate_cast to uint8 (round half to even, clipped). The float32 operations of the renderer's
    numpy/OpenCV path in its order: the same bits (test_frame_kernel.py), ~3× faster on a 640 × 480 frame with
    every effect (one pass instead of four; the noise window's reads bound it)."""

    def __init__(self) -> None:
        self._function = _library().lib.fpr_frame_finish

    def finish(self, image: np.ndarray, table: np.ndarray | None, row_terms: np.ndarray | None,
               column_terms: np.ndarray | None, noise: np.ndarray | None) -> np.ndarray:
        """``image`` finished in place (see the class) and returned."""
        if image.dtype != np.uint8 or image.ndim != 2 or not image.flags.c_contiguous or not image.flags.writeable:
            raise ValueError("frame kernel: expected a writeable C-contiguous 2-D uint8 image")
        height, width = image.shape
        if (row_terms is None) != (column_terms is None):
            raise ValueError("frame kernel: the gradient needs both row and column terms")
        noise_address, noise_stride = None, 0
        if noise is not None:
            if (noise.dtype != np.float32 or noise.shape != image.shape or noise.strides[1] != 4
                    or noise.strides[0] % 4 != 0):
                raise ValueError(f"frame kernel: expected a float32 noise window of shape {image.shape} with unit "
                                 "column stride")
            noise_address, noise_stride = noise.ctypes.data, noise.strides[0] // 4
        status = self._function(height, width, image.ctypes.data, _float32_address(table, 256),
                                _float32_address(row_terms, height), _float32_address(column_terms, width),
                                noise_address, noise_stride)
        if status != _OK:
            raise ValueError(f"frame kernel refused a {height} × {width} frame (status {status})")
        return image


class QuadKernel:
    """:meth:`QuadrotorFleet.control` and :meth:`QuadrotorFleet.step` in C for one fleet (constants frozen at
    construction, as the Python fleet reads them at construction too)."""

    def __init__(self, fleet) -> None:
        library = _library()
        n = fleet.n
        if n > library.max_legs:
            raise RuntimeError(f"n = {n} > {library.max_legs} vehicles of the compiled kernel")
        self.n = n
        self.model = _quad_model(fleet)
        self._model_pointer = ctypes.addressof(self.model)
        self._control = library.lib.fpr_quad_control
        self._step = library.lib.fpr_quad_step
        self._control_layout = library.layout(_CONTROL, n)
        self._quad_layout = library.layout(_QUAD, n)
        self._control_io = np.zeros(self._control_layout["size"])
        self._quad_io = np.zeros(self._quad_layout["size"])
        self._control_pointer = self._control_io.ctypes.data
        self._quad_pointer = self._quad_io.ctypes.data
        self._unit_factors = [1.0] * (4 * n)

    def control(self, fleet, command, rates: list[list[float]], on_ground: list[bool]) -> bool:
        """Run the controller update into ``fleet``; False (nothing changed) when the inputs are not the plain
        (n, ·) arrays of finite attitudes the kernel handles: the caller then runs the Python reference, which
        raises or handles them exactly as before."""
        n = self.n
        layout = self._control_layout
        try:
            command_quat = np.asarray(command.quat, dtype=float)
            thrust = np.atleast_1d(np.asarray(command.thrust, dtype=float))
            armed = np.atleast_1d(np.asarray(command.armed, dtype=bool))
            feedforward = (None if command.rate_feedforward is None
                           else np.asarray(command.rate_feedforward, dtype=float))
        except (TypeError, ValueError):
            return False
        if (command_quat.shape != (n, 4) or thrust.shape != (n,) or armed.shape != (n,) or len(rates) != n
                or (feedforward is not None and feedforward.shape != (n, 3))):
            return False
        io = self._control_io
        f_max = fleet.f_max
        io[:layout["setpoint"]] = list(chain(
            chain.from_iterable(fleet._quat), chain.from_iterable(rates), chain.from_iterable(fleet._previous_rate),
            chain.from_iterable(fleet._rate_integral), command_quat.ravel().tolist(), thrust.tolist(),
            armed.tolist(), on_ground, [0.0] * (3 * n) if feedforward is None else feedforward.ravel().tolist(),
            np.asarray(f_max, dtype=float).tolist()))
        if self._control(self._model_pointer, self._control_pointer, 0 if feedforward is None else 1) != _OK:
            return False
        out = io.tolist()
        a, b, c = layout["setpoint"], layout["integral_out"], layout["commands"]
        fleet._rate_setpoint = [out[a + 3 * i:a + 3 * i + 3] for i in range(n)]
        fleet._rate_integral = [out[b + 3 * i:b + 3 * i + 3] for i in range(n)]
        fleet._previous_rate = [list(r) for r in rates]
        fleet._rotor_commands = [out[c + 4 * i:c + 4 * i + 4] for i in range(n)]
        return True

    def step(self, fleet, dt: float, moments: list[list[float]]) -> None:
        """(2.92) + motor lag + battery by ``dt`` into ``fleet`` (see QuadrotorFleet.step)."""
        n = self.n
        layout = self._quad_layout
        battery = fleet.battery
        if len(moments) != n or any(len(m) != 3 for m in moments):
            raise ValueError(f"body moments: expected {n} rows of 3, got {moments}")
        io = self._quad_io
        factors = fleet.rotor_factors
        io[:layout["current"]] = list(chain(
            chain.from_iterable(fleet._quat), chain.from_iterable(fleet._rate), chain.from_iterable(fleet._rotors),
            chain.from_iterable(fleet._rotor_commands), chain.from_iterable(moments), battery._charge_used,
            self._unit_factors if factors is None else chain.from_iterable(factors)))
        self._step(self._model_pointer, self._quad_pointer, dt, 0 if factors is None else 1)
        out = io.tolist()
        _unpack_fleet(fleet, out, layout, n)


def _unpack_fleet(fleet, out: list[float], layout: dict[str, int], n: int) -> None:
    q, w, r, c, a = layout["quat"], layout["rate"], layout["rotors"], layout["charge"], layout["current"]
    fleet._quat = [out[q + 4 * i:q + 4 * i + 4] for i in range(n)]
    fleet._rate = [out[w + 3 * i:w + 3 * i + 3] for i in range(n)]
    fleet._rotors = [out[r + 4 * i:r + 4 * i + 4] for i in range(n)]
    fleet.battery._charge_used = out[c:c + n]
    fleet.battery._current = out[a:a + n]


class PlantKernel:
    """The whole of :meth:`Plant.step` after the scheduling (controller update, payload, wind, wrench) in one C
    call: structure RK4 with the environment forces, ground anchors, joint-offset and landing-gear moments,
    quadrotor RK4, motors and battery. Constants are copied from the plant at construction."""

    def __init__(self, plant) -> None:
        library = _library()
        n = plant.n
        if n > library.max_legs:
            raise RuntimeError(f"n = {n} > {library.max_legs} legs of the compiled kernel")
        self.n = n
        self.model = model = library.plant_model_type()
        sd = plant.structure
        env = plant.environment
        scenario = plant.scenario
        model.n = n
        model.leg_length = float(sd.leg_length)
        for i in range(n):
            _fill(model.anchors[i], sd.anchors[i].tolist())
            _fill(model.joint_axes[i], sd.joint_axes[i].tolist())
            model.cos_alpha[i] = float(sd.cos_alpha[i])
            model.sin_alpha[i] = float(sd.sin_alpha[i])
            model.uav_masses[i] = float(plant.uav_masses[i])
        _fill(model.gravity, plant._gravity)
        model.gravity_magnitude = float(plant.params.gravity)
        _fill(model.joint_offset, plant._joint_offset)
        ground = scenario.ground
        model.ground_enabled = int(bool(ground.enabled))
        model.ground_height = float(ground.height)
        model.ground_stiffness = float(ground.stiffness)
        model.ground_damping = float(ground.damping)
        model.ground_tangential_stiffness = float(ground.tangential_stiffness)
        model.ground_tangential_damping = float(ground.tangential_damping)
        model.ground_friction = float(ground.friction)
        model.gear_height = float(plant.gear)
        model.gear_radius = float(scenario.quadrotor.landing_gear_radius)
        model.uav_drag, model.leg_drag, model.platform_drag = (float(plant._uav_drag), float(plant._leg_drag),
                                                               float(plant._platform_drag))
        board = env.board
        model.board_enabled = int(plant._board_enabled)
        _fill(model.board_normal, env._board_normal)
        _fill(model.board_point, env._board_point)
        model.board_stiffness = float(board.stiffness)
        model.board_damping = float(board.damping)
        model.board_friction = float(board.friction)
        _fill(model.board_u, env._board_u)
        _fill(model.board_v, env._board_v)
        _fill(model.board_half_size, env.board_half_size)
        model.board_contact_depth = float(board.contact_depth)
        _fill(model.end_effector, plant._end_effector)
        stops = plant._joint_stops
        model.joint_stops_enabled = int(stops is not None)
        if stops is not None:
            (model.joint_stop_lower, model.joint_stop_upper, model.joint_stop_stiffness,
             model.joint_stop_damping) = stops
        model.quad = _quad_model(plant.fleet)
        if float(scenario.quadrotor.arm_length) != model.quad.arm:
            raise RuntimeError("landing-gear arm differs from the fleet's arm length")
        self._model_pointer = ctypes.addressof(model)
        self._function = library.lib.fpr_plant_step
        self._layout = layout = library.layout(_PLANT, n)
        self._io = np.zeros(layout["size"])
        self._io_pointer = self._io.ctypes.data
        self._inputs = layout["current"]
        self._basis = None
        self._basis_pointer = 0
        self._anchors = None
        self._anchors_pointer = 0
        self._still_air = [0.0] * (3 * (1 + 2 * n))
        self._unit_factors = [1.0] * (4 * n)
        self._no_forces = [0.0] * (3 * n)

    def advance(self, plant) -> bool:
        """Advance ``plant`` by one step in C (Plant.step's body after the scheduling); False (nothing
        changed) when the kernel refuses (singular mass matrix): the caller runs the Python reference."""
        n = self.n
        fleet = plant.fleet
        wind = plant._air_list  # 3 (1 + 2n) air velocities [P, B_1..B_n, leg middles] or None
        factors = fleet.rotor_factors  # (n, 4) or None (realism)
        forces = plant._uav_force_list  # (n, 3) or None (realism: rotor drag)
        io = self._io
        io[:self._inputs] = list(chain(
            plant._x_list, chain.from_iterable(fleet._quat), chain.from_iterable(fleet._rate),
            chain.from_iterable(fleet._rotors), chain.from_iterable(fleet._rotor_commands),
            fleet.battery._charge_used, chain.from_iterable(plant._tip_velocity_list), plant._yaw_anchors,
            self._still_air if wind is None else wind, plant._platform_force_list, plant._platform_moment_list,
            self._unit_factors if factors is None else chain.from_iterable(factors),
            self._no_forces if forces is None else chain.from_iterable(forces)))
        basis = plant.structure._basis
        if basis is not self._basis:  # a new basis after a payload change
            self._basis_pointer = _pointer(basis, (1 + 4 * n, (6 + n) ** 2))
            self._basis = basis
        anchors = plant.environment.ground.anchors  # updated in place by the kernel
        if anchors is not self._anchors:
            self._anchors_pointer = _pointer(anchors, (n + 1, 2))
            self._anchors = anchors
        flags = ((_FLAG_IDEAL if plant.ideal_attitude else 0) | (0 if wind is None else _FLAG_WIND)
                 | (0 if factors is None else _FLAG_FACTORS) | (0 if forces is None else _FLAG_UAV_FORCE))
        status = self._function(self._model_pointer, self._basis_pointer, self._anchors_pointer, self._io_pointer,
                                plant.dt, flags)
        if status != _OK:
            return False
        out = io.tolist()
        layout = self._layout
        x, v, a, y = layout["x"], layout["tip_velocity"], layout["tip_acceleration"], layout["yaw_anchors"]
        p = layout["tip_position"]
        plant._set_x(out[x:x + 13 + 2 * n])
        plant._tip_velocity_list = [out[v + 3 * i:v + 3 * i + 3] for i in range(n)]
        # the tip kinematics of the new state (the kernel computed them): the next step's fan evaluation uses them
        plant._tips = ([tuple(out[p + 3 * i:p + 3 * i + 3]) for i in range(n)],
                       [tuple(v_i) for v_i in plant._tip_velocity_list])
        plant._tip_acceleration_list = [out[a + 3 * i:a + 3 * i + 3] for i in range(n)]
        plant._yaw_anchors = out[y:y + n]
        plant._contact_force = out[layout["contact"]]
        plant._ground_active = out[layout["ground_active"]] != 0.0
        _unpack_fleet(fleet, out, layout, n)
        return True
