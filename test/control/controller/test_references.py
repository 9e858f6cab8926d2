"""References: analytic derivatives, Eq. 38, unit conversion, waypoint files."""

import math

import numpy as np
import pytest
from pneu_control.controller.params import ParamError, ReferenceParams
from pneu_control.controller.references import Waypoints, load_waypoints, make_reference
from pneu_msgs_py.params.core import validate


def _ref(axis="linear", **kw):
    return make_reference(validate(ReferenceParams(**kw)), axis)


def _check_derivatives(ref, ts, h=1e-6, rtol=1e-5, atol=1e-9):
    for t in ts:
        r_m, rd_m, _ = ref(t - h)
        r_p, rd_p, _ = ref(t + h)
        _r, rd, rdd = ref(t)
        scale = max(abs(rd), abs(rdd), 1e-12)
        assert (r_p - r_m) / (2 * h) == pytest.approx(rd, rel=rtol, abs=atol + 1e-4 * scale)
        assert (rd_p - rd_m) / (2 * h) == pytest.approx(rdd, rel=rtol, abs=atol + 1e-4 * scale)


def test_eq38_smooth_step_matches_paper_formula():
    ref = _ref(kind="smooth_step", offset=0.0, target=120.0 / math.pi, duration_s=4.0)
    for t in np.linspace(0.0, 6.0, 61):
        tt = min(t, 4.0)
        x_mm = -(60 / math.pi**2) * math.sin(0.5 * math.pi * tt) + 30 * tt / math.pi  # Eq. 38
        assert ref(t)[0] == pytest.approx(x_mm / 1000.0, abs=1e-15)
    assert ref(4.0)[0] == pytest.approx(0.120 / math.pi)
    for t in (0.0, 4.0, 5.0):
        assert ref(t)[1] == pytest.approx(0.0, abs=1e-15) and ref(t)[2] == pytest.approx(
            0.0, abs=1e-15
        )


@pytest.mark.parametrize(
    "kw",
    [
        {"kind": "sine", "amplitude": 20.0, "frequency_hz": 0.25, "offset": 5.0},
        {"kind": "smooth_step", "offset": -10.0, "target": 30.0, "duration_s": 2.0, "t0_s": 0.5},
        {"kind": "ramp", "offset": 1.0, "slope": 3.0, "duration_s": 2.0},
        {"kind": "constant", "value": 7.0},
    ],
)
@pytest.mark.parametrize("axis", ["linear", "rotary"])
def test_analytic_derivatives_and_units(kw, axis):
    ref = _ref(axis, **kw)
    _check_derivatives(ref, np.linspace(0.013, 3.9, 37))
    scale = 1000.0 if axis == "linear" else 60.0 / (2 * math.pi)
    if kw["kind"] == "sine":
        assert ref(1.0)[0] * scale == pytest.approx(5.0 + 20.0)  # sin(2π·0.25·1) = 1
    if kw["kind"] == "constant":
        assert ref(3.0) == (7.0 / scale, 0.0, 0.0)
    if kw["kind"] == "ramp":
        assert ref(1.0)[0] * scale == pytest.approx(4.0) and ref(5.0)[0] * scale == pytest.approx(
            7.0
        )


def test_rotary_constant_800_rpm_is_83_8_rad_s():
    assert _ref("rotary", kind="constant", value=800.0)(1.0)[0] == pytest.approx(
        800 * 2 * math.pi / 60
    )


def _write(tmp_path, name, text):
    f = tmp_path / name
    f.write_text(text)
    return str(f)


def test_waypoints_csv_and_yaml_agree_and_are_c2(tmp_path):
    rows = [(0.0, 0.0), (1.0, 10.0), (1.5, 10.0), (3.0, -5.0), (4.0, 2.0)]
    csv_f = _write(tmp_path, "w.csv", "t,value\n" + "".join(f"{t},{v}\n" for t, v in rows))
    yaml_f = _write(tmp_path, "w.yaml", "points:\n" + "".join(f"  - [{t}, {v}]\n" for t, v in rows))
    a = _ref(kind="waypoints", file=csv_f)
    b = _ref(kind="waypoints", file=yaml_f)
    for t in np.linspace(-0.5, 4.5, 101):
        assert a(t) == b(t)
    for t, v in rows:  # passes through every knot, in m
        assert a(t)[0] == pytest.approx(v / 1000.0, abs=1e-15)
    _check_derivatives(a, [0.3, 0.7, 1.2, 2.0, 2.9, 3.5])
    for t, _ in rows:  # r, ṙ, r̈ continuous across knots
        lo, hi = a(t - 1e-9), a(t + 1e-9)
        for x, y, tol in zip(lo, hi, (1e-9, 1e-6, 1e-3)):
            assert x == pytest.approx(y, abs=tol)
    # monotone run between 1.5 and 3.0 s (10 → −5): no overshoot beyond the knots
    seg = [a(t)[0] * 1000 for t in np.linspace(1.5, 3.0, 200)]
    assert max(seg) <= 10.0 + 1e-9 and min(seg) >= -5.0 - 1e-9


def test_waypoints_hold_before_and_after():
    w = Waypoints([0.5, 1.0], [1.0, 2.0])
    assert w(0.0) == (1.0, 0.0, 0.0) and w(2.0) == (2.0, 0.0, 0.0)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (
            "t,value\n0,0\n1,1\n1,2\n",
            r"reference.file\[2\].t: 1.0 refused; allowed: strictly increasing",
        ),
        ("t,value\n0,0\n2,1\n1,2\n", r"reference.file\[2\].t: 1.0 refused"),
        (
            "t,value\n0,0\n1,nan\n",
            r"reference.file\[1\].value: 'nan' refused; allowed: a finite number",
        ),
        ("t,value\n0,0\n", "at least two waypoints"),
        ("t,value\n0,0\n1,abc\n", r"reference.file\[1\].value: 'abc' refused"),
    ],
)
def test_bad_waypoint_files_refused(tmp_path, text, match):
    f = _write(tmp_path, "bad.csv", text)
    with pytest.raises(ParamError, match=match):
        load_waypoints(f)
    with pytest.raises(ParamError, match=match):
        _ref(kind="waypoints", file=f)


def test_bad_yaml_waypoints_and_missing_file(tmp_path):
    f = _write(tmp_path, "bad.yaml", "t: [0.0, 1.0, 0.5]\nvalue: [0.0, 1.0, 2.0]\n")
    with pytest.raises(ParamError, match="strictly increasing"):
        load_waypoints(f)
    f = _write(tmp_path, "nan.yaml", "- [0.0, 0.0]\n- [1.0, .nan]\n")
    with pytest.raises(ParamError, match="finite"):
        load_waypoints(f)
    with pytest.raises(ParamError, match="reference.file: '/no/such.csv' refused"):
        load_waypoints("/no/such.csv")


def test_nyquist_checked_when_building():
    with pytest.raises(
        ParamError, match=r"reference.frequency_hz: 600.0 refused; allowed: \[0.00166667, 500\) Hz"
    ):
        _ref(kind="sine", frequency_hz=600.0)
    # the lower end: one whole period inside the longest run (the duration cap, 600 s)
    with pytest.raises(ParamError, match=r"frequency_hz: 1e-300 refused; allowed: \[1/600"):
        validate(ReferenceParams(kind="sine", frequency_hz=1e-300))
    with pytest.raises(ParamError, match="reference.kind"):
        make_reference(ReferenceParams(kind="square"), "linear")  # unvalidated object
