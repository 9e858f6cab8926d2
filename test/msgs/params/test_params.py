"""The parameter framework: strict loading, range errors, whole-set updates."""

from dataclasses import dataclass

import pytest
from pneu_msgs_py.params.core import ParamError, describe, flatten, from_dict, param, with_updates


@dataclass(frozen=True)
class Inner:
    epsilon: float = param(1200.0, unit="mm/s^3", lo=0.0, lo_open=True, desc="reaching gain")
    n: int = param(3, lo=1, hi=10)


@dataclass(frozen=True)
class Outer:
    algorithm: str = param("pid", choices=("pid", "ladrc", "eso_smc"))
    omega_0: float = param(25.0, unit="rad/s", lo=0.0, hi=500.0)
    inner: Inner = param(Inner)
    table: tuple[float, ...] = param((0.0, 1.0), unit="-")

    def _check(self):
        if self.algorithm == "ladrc" and self.omega_0 < 1.0:
            raise ParamError("omega_0", self.omega_0, "[1, 500] rad/s with ladrc")


def test_defaults_and_flatten():
    o = from_dict(Outer, {}, strict=False)
    assert flatten(o) == {
        "algorithm": "pid",
        "omega_0": 25.0,
        "inner.epsilon": 1200.0,
        "inner.n": 3,
        "table": [0.0, 1.0],  # a list, as YAML writes it
    }


def test_strict_missing_key_named():
    with pytest.raises(
        ParamError, match=r"^inner: missing; required: the parameter group epsilon, n"
    ):
        from_dict(Outer, {"algorithm": "pid", "omega_0": 1.0}, strict=True)


def test_unknown_key_and_wrong_type():
    with pytest.raises(ParamError, match="inner.bogus"):
        from_dict(Outer, {"inner": {"bogus": 1}}, strict=False)
    with pytest.raises(ParamError, match="omega_0: 'fast' refused; allowed: a number"):
        from_dict(Outer, {"omega_0": "fast"}, strict=False)
    with pytest.raises(ParamError, match=r"inner.n: 2.5 refused; allowed: an integer"):
        from_dict(Outer, {"inner": {"n": 2.5}}, strict=False)


def test_range_message_names_bounds():
    with pytest.raises(
        ParamError, match=r"inner.epsilon: -1.0 refused; allowed: \(0, inf\) mm/s\^3"
    ):
        from_dict(Outer, {"inner": {"epsilon": -1.0}}, strict=False)
    with pytest.raises(ParamError, match=r"allowed: \(0, inf\)"):
        from_dict(Outer, {"inner": {"epsilon": 0.0}}, strict=False)  # open bound, exactly at it
    assert from_dict(Outer, {"omega_0": 500.0}, strict=False).omega_0 == 500.0  # closed bound


def test_with_updates_is_atomic():
    o = from_dict(Outer, {}, strict=False)
    with pytest.raises(ParamError, match="omega_0"):
        with_updates(o, {"algorithm": "ladrc", "omega_0": 0.5})  # each valid alone, not together
    assert o.algorithm == "pid" and o.omega_0 == 25.0
    o2 = with_updates(o, {"inner.epsilon": 900, "algorithm": "ladrc"})
    assert o2.inner.epsilon == 900.0 and isinstance(o2.inner.epsilon, float)
    assert o.inner.epsilon == 1200.0


@pytest.mark.parametrize(
    ("value", "refusal"),
    [
        ((0.0, float("nan"), 1.0), r"^table\[1\]: nan refused; allowed: a finite number$"),
        ((0.0, 1.0, float("inf")), r"^table\[2\]: inf refused; allowed: a finite number$"),
        ((True, 1.0), r"^table\[0\]: True refused; allowed: a finite number$"),
        ((0.0, "1"), r"^table\[1\]: '1' refused; allowed: a finite number$"),
        (3.0, r"^table: 3.0 refused; allowed: a list of numbers$"),
    ],
)
def test_a_list_of_numbers_names_the_bad_element(value, refusal):
    o = from_dict(Outer, {}, strict=False)
    with pytest.raises(ParamError, match=refusal):
        with_updates(o, {"table": value})


def test_a_list_of_numbers_comes_back_a_tuple_of_floats():
    o = from_dict(Outer, {}, strict=False)
    for value in ([0, 2.5, 3], (0.25, 0.5), [0.125]):
        got = with_updates(o, {"table": value}).table
        assert got == tuple(float(v) for v in value)
        assert type(got) is tuple and all(type(v) is float for v in got)


def test_describe_specs():
    specs = {s.name: s for s in describe(Outer)}
    assert specs["inner.epsilon"].lo == 0.0 and "mm/s^3" in specs["inner.epsilon"].description
    assert specs["algorithm"].choices == ("pid", "ladrc", "eso_smc")


def test_one_spec_parser_for_references_faults_and_launch_arguments():
    from pneu_msgs_py.params.spec import parse_spec, parse_value

    assert parse_spec("sine:amplitude=20,frequency_hz=0.25", "--reference") == (
        "sine",
        {"amplitude": 20, "frequency_hz": 0.25},
    )
    assert parse_spec(" constant ", "--reference") == ("constant", {})
    assert parse_value("3e5") == 3e5 and parse_value("pid") == "pid" and parse_value("1") == 1
    for text, msg in (
        ("sine:amplitude=20,amplitude=5", "--reference sine: 'amplitude' refused; allowed: each key once"),
        ("sine:amplitude", "--reference sine: 'amplitude' refused; allowed: key=value"),
        ("sine:=3", "--reference sine: '=3' refused; allowed: key=value"),
        (":amplitude=3", "--reference: ':amplitude=3' refused; allowed: KIND[:key=value,...] with a KIND"),
    ):  # fmt: skip
        with pytest.raises(ParamError) as err:
            parse_spec(text, "--reference")
        assert str(err.value) == msg
