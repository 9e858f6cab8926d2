"""Every algorithm's kernels compiled by numba give the Python results bit for bit.

Each :class:`~pneu_control.algorithms.base.KernelAlgorithm` in ``ALGORITHM_CLASSES``
runs one input sequence twice: in Python (its records, as the runner runs it) and
inside a small ``@njit`` driver that calls the same ``start``/``update`` kernels on
numpy structured records (``RecordType.array``), as the compiled loop does. The
commands and every state field after every step must be equal as bits (NaN = NaN).

The inputs come from a crude closed loop (a damped double integrator per axis, in
the algorithm's units, laser-like noise, a transport-delay pipe) so that the laws
saturate, leave and re-enter the boundary layer and the anti-windup acts; a warm
restart mid-run (``u_prev`` and a hint, as on a run-time switch) and NaN pressure
samples are included.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit
from pneu_control.algorithms import ALGORITHM_CLASSES
from pneu_control.algorithms.base import MAX_HISTORY, STEP_INPUT, KernelAlgorithm
from pneu_control.controller.params import load_controller_params
from pneu_msgs_py.params.paths import config_file

PAPER = config_file("controllers.yaml")
RETUNED = config_file("controllers_retuned.yaml")
N = 1500  # samples per case
KIND_UPDATE, KIND_START = 0, 1
# narrower, asymmetric valve limits, per axis (the rotary plant needs a fraction of a volt)
LIMITS = {
    "linear": {"limits.u_min": 3.0, "limits.u_max": 7.5},
    "rotary": {"limits.u_min": 4.8, "limits.u_max": 5.15},
}

# (algorithm, axis, gains file, overrides): the options of every algorithm
PLUS_VLIN = {"eso_smc_plus.valve_linearisation": True}
PLUS_DC = {"eso_smc_plus.delay_compensation": True, "transport_delay_samples": 2}
CASES = [
    ("pid", "linear", PAPER, {}),
    ("pid", "rotary", RETUNED, {"pid.derivative_on": "measurement"}),
    ("pid", "linear", RETUNED, {"pid.anti_windup": "back_calculation"}),
    ("pid", "linear", PAPER, {"pid.anti_windup": "none", "pid.y_filter_tf": 0.003}),
    ("ladrc", "linear", PAPER, {}),
    ("ladrc", "rotary", RETUNED, {"ladrc.accel_feedforward": True}),
    ("ladrc", "linear", RETUNED, {"ladrc.delay_compensation": True, "transport_delay_samples": 2}),
    ("eso_smc", "rotary", PAPER, {}),
    ("eso_smc", "linear", RETUNED, {}),
    (
        "eso_smc",
        "linear",
        PAPER,
        {"eso_smc.delay_compensation": True, "transport_delay_samples": 2},
    ),
    ("eso_smc", "linear", RETUNED, {"eso_smc.integral_anti_windup": False}),
    ("eso_smc", "rotary", RETUNED, {"eso_smc.friction_compensation": True}),
    (
        "eso_smc",
        "rotary",
        RETUNED,
        {"eso_smc.friction_compensation": True, "rotary_model": "angle"},
    ),
    ("pid", "rotary", PAPER, {"rotary_control": "angle"}),
    ("ladrc", "rotary", RETUNED, {"rotary_control": "angle"}),
    ("eso_smc", "rotary", PAPER, {"rotary_control": "angle"}),
    ("coast", "rotary", PAPER, {"rotary_control": "angle"}),
    ("coast", "rotary", RETUNED, {"rotary_control": "angle", "coast.overshoot": "hold"}),
    ("pva", "rotary", PAPER, {"rotary_control": "angle"}),
    # every remainder at rest pulsed; the whole disturbance estimate taken out
    (
        "pva",
        "rotary",
        RETUNED,
        {"rotary_control": "angle", "pva.pulse_max_deg": 400.0, "pva.disturbance_share": 1.0},
    ),
    ("eso_smc_plus", "linear", PAPER, {}),  # position, friction feed-forward
    ("eso_smc_plus", "linear", PAPER, {"eso_smc_plus.friction_feedforward": False}),
    ("eso_smc_plus", "linear", PAPER, {**PLUS_DC}),
    ("eso_smc_plus", "linear", PAPER, {**PLUS_DC, **PLUS_VLIN}),
    ("eso_smc_plus", "linear", PAPER, {"eso_smc_plus.linear_model": "force"}),
    ("eso_smc_plus", "linear", PAPER, {"eso_smc_plus.linear_model": "force", **PLUS_VLIN}),
    ("eso_smc_plus", "linear", RETUNED, {"eso_smc_plus.reference_derivatives": "td"}),
    ("eso_smc_plus", "rotary", PAPER, {}),  # angle observer, delay compensation
    ("eso_smc_plus", "rotary", PAPER, {"eso_smc_plus.delay_compensation": False, **PLUS_VLIN}),
    ("eso_smc_plus", "rotary", PAPER, {**PLUS_DC, **PLUS_VLIN}),
    ("eso_smc_plus", "rotary", PAPER, {"eso_smc_plus.rotary_observer": "speed"}),
    ("eso_smc_plus", "rotary", PAPER, {"eso_smc_plus.rotary_observer": "speed", **PLUS_VLIN}),
    ("eso_smc_plus", "rotary", PAPER, {"rotary_model": "angle"}),  # analytic: speed inputs
    (
        "eso_smc_plus",
        "rotary",
        PAPER,
        {"rotary_model": "angle", "eso_smc_plus.reference_derivatives": "td", **PLUS_DC},
    ),
    (
        "eso_smc_plus",
        "rotary",
        PAPER,
        {
            "rotary_model": "angle",
            "eso_smc_plus.reference_derivatives": "td",
            "eso_smc_plus.rotary_observer": "speed",
            **PLUS_VLIN,
        },
    ),
]


def _case_id(case):
    alg, axis, file, over = case
    opts = ",".join(f"{k.split('.')[-1]}={v}" for k, v in over.items())
    return f"{alg}-{axis}-{'paper' if file == PAPER else 'retuned'}-{opts or 'default'}"


_DRIVERS: dict[str, object] = {}


def _driver(cls: type[KernelAlgorithm]):
    """One compiled driver per algorithm (its record types), calling its own kernels."""
    if cls.name in _DRIVERS:
        return _DRIVERS[cls.name]
    start = cls.KERNEL.start
    update = cls.KERNEL.update

    @njit(error_model="numpy")
    def drive(c, s, s_bytes, tab, inps, kinds, u_prev, hints, u_out, s_out):
        cr = c[0]
        sr = s[0]
        for i in range(inps.shape[0]):
            inp = inps[i]
            if kinds[i] == KIND_START:
                u = start(cr, sr, tab, inp, u_prev[i], hints[i, 0], hints[i, 1], hints[i, 2])
            else:
                u = update(cr, sr, tab, inp)
            u_out[i] = u
            s_out[i, :] = s_bytes

    _DRIVERS[cls.name] = drive
    return drive


def _inputs(alg: KernelAlgorithm, params, axis: str, seed: int):
    """A closed-loop input sequence for ``alg`` (run in Python to make it), see the docstring."""
    rng = np.random.default_rng(seed)
    T = params.sample_time_s
    d = params.transport_delay_samples
    u_n = params.limits.u_neutral
    linear = axis == "linear"
    angle_ctl = (not linear) and params.rotary_control == "angle"  # y = θ in °
    # input gain (mm/s²/V, °/s²/V, rpm/s²/V), damping (1/s)
    b, damp = (2400.0, 30.0) if linear else ((2.0e5, 20.0) if angle_ctl else (2.3e6, 60.0))
    angle_in = (not linear) and params.rotary_model == "angle" and alg.uses_td
    inps = STEP_INPUT.array(N)
    kinds = np.zeros(N, dtype=np.int64)
    u_prev = np.full(N, math.nan)
    hints = np.full((N, 3), math.nan)
    kinds[0] = KIND_START
    kinds[N // 2] = KIND_START  # a warm restart (a run-time switch)
    pipe = [u_n] * (d + 1)  # commands in V, oldest first: the valve's, then the d in flight
    x = v = th = th_r = 0.0  # plant output (mm | rpm), its rate, the angle (rpm·s), θ_r
    u = 0.0
    inp = STEP_INPUT.new()
    for k in range(N):
        t = k * T
        if linear:  # the 20 mm, 0.5 Hz sine, then a step to 55 mm (the command saturates)
            w = 2.0 * math.pi * 0.5
            r, r_dot = 20.0 * math.sin(w * t), 20.0 * w * math.cos(w * t)
            r_ddot = -20.0 * w * w * math.sin(w * t)
            if t > 0.9:
                r, r_dot, r_ddot = 55.0, 0.0, 0.0
            y = x + 0.05 * rng.standard_normal()  # laser noise
        elif angle_ctl:  # target angles 180° -> 540° -> 300° (an overshoot for a one-way drive)
            r = 180.0 if t <= 0.5 else (540.0 if t <= 1.0 else 300.0)
            r_dot = r_ddot = 0.0
            y = 0.09 * round(x / 0.09)  # encoder counts
        else:  # speed steps 800 -> 1500 -> 300 rpm
            r = 800.0 + (700.0 if t > 0.5 else 0.0) - (1200.0 if t > 1.0 else 0.0)
            r_dot = r_ddot = 0.0
            y = 15.0 * round(x / 15.0)  # quantised speed
        th_r += T * (0.0 if linear or angle_ctl else r)
        inp.y, inp.r, inp.r_dot, inp.r_ddot = y, r, r_dot, r_ddot
        if angle_in:  # the controller passes (θ, θ_r, ω_r, ω̇_r)
            inp.y, inp.r, inp.r_dot, inp.r_ddot = th, th_r, r, r_dot
        inp.u_applied = pipe[0] - u_n
        inp.theta = th
        nan_p = k % 97 == 13
        inp.p_c1 = math.nan if nan_p else 2.0e5 + 8.0e4 * math.tanh(0.3 * x + v * 1e-3)
        inp.p_c2 = 2.0e5 - 8.0e4 * math.tanh(0.3 * x)
        inp.n_hist = d + 1
        inp.history = [*pipe, *[0.0] * (MAX_HISTORY - d - 1)]
        inp.store(inps[k])
        if kinds[k] == KIND_START:
            if k > 0:
                u_prev[k] = u
                hints[k] = alg.hint
                if seed % 2:
                    hints[k, 2] = math.nan  # an algorithm without an acceleration estimate
            hint = tuple(hints[k])
            u = alg.start(inp, None if k == 0 else float(u_prev[k]), hint)
        else:
            u = alg.update(inp)
        # the plant over the sample, on the command on the valve: y'' = b u − c y' + a load
        acc = b * (pipe[0] - u_n) - damp * v + (200.0 if linear else 2.0e5) * math.sin(3.0 * t)
        th += T * x
        x += T * v
        v += T * acc
        pipe = [*pipe[1:], u + u_n]
    return inps, kinds, u_prev, hints


def _assert_bits(a: np.ndarray, b: np.ndarray, what: str) -> None:
    for name in a.dtype.names:
        x, y = a[name], b[name]
        if x.dtype.kind == "f":
            nan = np.isnan(x)
            assert np.array_equal(nan, np.isnan(y)), (what, name)
            same = x.view(np.int64) == y.view(np.int64)
            assert np.all(same | nan), (what, name, np.argmin(same | nan))
        else:
            assert np.array_equal(x, y), (what, name)


def test_every_kernel_algorithm_has_cases():
    kernel_algorithms = {n for n, c in ALGORITHM_CLASSES.items() if issubclass(c, KernelAlgorithm)}
    assert kernel_algorithms == {case[0] for case in CASES}


@pytest.mark.parametrize("case", CASES, ids=_case_id)
def test_compiled_kernels_equal_python_bit_for_bit(case):
    name, axis, file, overrides = case
    # narrower, asymmetric valve limits (every other case): the laws saturate
    limits = LIMITS[axis] if CASES.index(case) % 2 else {}
    params = load_controller_params(axis, file, {"algorithm": name, **limits, **overrides})
    cls = ALGORITHM_CLASSES[name]
    assert issubclass(cls, KernelAlgorithm)
    inps, kinds, u_prev, hints = _inputs(cls(params, axis), params, axis, seed=len(overrides))

    # Python: a fresh algorithm, the same inputs
    py = cls(params, axis)
    c = py.CONSTANTS.array(1)
    py.c.store(c[0])
    s = py.STATE.array(1)
    py.st.store(s[0])
    tab = np.asarray(py.tab, dtype=np.float64)
    u_py = np.empty(N)
    s_py = py.STATE.array(N)
    inp = STEP_INPUT.new()
    for k in range(N):
        inp.load(inps[k])
        if kinds[k] == KIND_START:
            up = None if math.isnan(u_prev[k]) else float(u_prev[k])
            u_py[k] = py.start(inp, up, tuple(float(h) for h in hints[k]))
        else:
            u_py[k] = py.update(inp)
        py.st.store(s_py[k])

    # compiled: the same kernels on numpy records
    u_nb = np.empty(N)
    s_nb = np.zeros((N, s.dtype.itemsize), dtype=np.uint8)
    _driver(cls)(c, s, s.view(np.uint8), tab, inps, kinds, u_prev, hints, u_nb, s_nb)

    _assert_bits(u_py.view([("u", "f8")]), u_nb.view([("u", "f8")]), "command")
    _assert_bits(s_py, s_nb.view(s.dtype).reshape(N), "state")
    # the sequence exercised the law: with the narrow limits the command saturates at times
    assert np.all(np.isfinite(u_py))
    if limits:
        lim = params.limits
        at_limit = (u_py <= lim.u_min - lim.u_neutral) | (u_py >= lim.u_max - lim.u_neutral)
        assert at_limit.any()
