"""ROS parameter plumbing of the shells, tested without ROS.

Descriptors are built with rosbags' Jazzy typestore classes, which have the
same fields as rclpy's ``rcl_interfaces`` messages.
"""

from __future__ import annotations

import dataclasses

from pneu_msgs_py.params.core import ParamError, flatten, param, validate
from pneu_msgs_py.params.ros import (
    PARAMETER_TYPE,
    allowed_text,
    coerce_value,
    declarations,
    descriptor_fields,
    specs_by_name,
    validate_updates,
    values_to_overrides,
)
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_JAZZY)
ParameterDescriptor = TS.types["rcl_interfaces/msg/ParameterDescriptor"]
FloatingPointRange = TS.types["rcl_interfaces/msg/FloatingPointRange"]
IntegerRange = TS.types["rcl_interfaces/msg/IntegerRange"]
ParameterType = TS.types["rcl_interfaces/msg/ParameterType"]


@dataclasses.dataclass(frozen=True)
class Eso:
    omega_0: float = param(
        25.0, unit="rad/s", desc="observer bandwidth", lo=0.0, lo_open=True, hi=1e4
    )
    epsilon: float = param(1200.0, unit="1/s", desc="switching gain", lo=0.0, lo_open=True)
    h: float = param(0.001, unit="s", desc="observer step", lo=1e-5, hi=0.1)

    def _check(self):
        # the discrete ESO is stable only for omega_0 * h small enough
        if self.omega_0 * self.h >= 0.5:
            raise ParamError("omega_0", self.omega_0, f"omega_0 * h < 0.5 (h = {self.h:g} s)")


@dataclasses.dataclass(frozen=True)
class Ctrl:
    algorithm: str = param("eso_smc", desc="control law", choices=("pid", "ladrc", "eso_smc"))
    n_avg: int = param(4, desc="samples averaged", lo=1, hi=64)
    enabled: bool = param(True, desc="output enabled")
    period_s: float = param(0.001, unit="s", desc="sample period", lo=1e-4, hi=0.1, read_only=True)
    table: tuple[float, ...] = param((0.0, 1.0), desc="a table")
    eso_smc: Eso = param(Eso)


def test_parameter_type_constants_match_jazzy():
    assert PARAMETER_TYPE[bool] == ParameterType.PARAMETER_BOOL
    assert PARAMETER_TYPE[int] == ParameterType.PARAMETER_INTEGER
    assert PARAMETER_TYPE[float] == ParameterType.PARAMETER_DOUBLE
    assert PARAMETER_TYPE[str] == ParameterType.PARAMETER_STRING
    assert PARAMETER_TYPE[list] == ParameterType.PARAMETER_DOUBLE_ARRAY


def test_declarations_cover_every_field_with_jazzy_descriptors():
    params = validate(Ctrl())
    decls = declarations(params, ParameterDescriptor, FloatingPointRange, IntegerRange)
    names = [d[0] for d in decls]
    assert names == list(flatten(params))
    by = {name: (value, desc) for name, value, desc in decls}
    value, desc = by["eso_smc.omega_0"]
    assert value == 25.0 and isinstance(value, float)
    assert desc.type == ParameterType.PARAMETER_DOUBLE
    assert "observer bandwidth" in desc.description and "rad/s" in desc.description
    assert [(r.from_value, r.to_value, r.step) for r in desc.floating_point_range] == [
        (0.0, 1e4, 0.0)
    ]
    assert desc.additional_constraints == "(0, 10000] rad/s"
    # one-sided bound: no descriptor range (rclpy would need inf), the words say it
    _, desc = by["eso_smc.epsilon"]
    assert desc.floating_point_range == [] and desc.additional_constraints == "(0, inf) 1/s"
    assert by["period_s"][1].read_only is True and by["eso_smc.h"][1].read_only is False
    _, desc = by["n_avg"]
    assert desc.type == ParameterType.PARAMETER_INTEGER
    assert [(r.from_value, r.to_value, r.step) for r in desc.integer_range] == [(1, 64, 0)]
    value, desc = by["algorithm"]
    assert value == "eso_smc" and desc.additional_constraints == "one of pid, ladrc, eso_smc"
    value, desc = by["table"]
    assert value == [0.0, 1.0] and desc.type == ParameterType.PARAMETER_DOUBLE_ARRAY
    assert by["enabled"][0] is True and by["enabled"][1].type == ParameterType.PARAMETER_BOOL


def test_declarations_take_defaults_from_the_loaded_object():
    params = validate(Ctrl(eso_smc=Eso(epsilon=900.0)))
    by = {
        n: v
        for n, v, _ in declarations(params, ParameterDescriptor, FloatingPointRange, IntegerRange)
    }
    assert by["eso_smc.epsilon"] == 900.0


def test_descriptor_fields_are_exactly_the_jazzy_message_fields():
    spec = specs_by_name(Ctrl)["eso_smc.omega_0"]
    fields = descriptor_fields(spec)
    jazzy = [f for f in ParameterDescriptor.__dataclass_fields__ if not f.startswith("__")]
    assert sorted(fields) == sorted(jazzy)


def test_coerce_value_int_to_double_and_arrays():
    specs = specs_by_name(Ctrl)
    eps = coerce_value(specs["eso_smc.epsilon"], 900)
    assert eps == 900.0 and isinstance(eps, float)
    assert coerce_value(specs["n_avg"], 3) == 3 and isinstance(coerce_value(specs["n_avg"], 3), int)
    assert (
        coerce_value(specs["eso_smc.epsilon"], True) is True
    )  # bool stays for validation to refuse
    import array

    assert coerce_value(specs["table"], array.array("d", [1.0, 2.0])) == [1.0, 2.0]


def test_update_accepted_returns_new_params_and_keeps_old():
    old = validate(Ctrl())
    ok, reason, new = validate_updates(old, [("eso_smc.epsilon", 900)])
    assert ok and reason == ""
    assert new.eso_smc.epsilon == 900.0 and old.eso_smc.epsilon == 1200.0


def test_update_out_of_range_is_refused_naming_parameter_and_range():
    old = validate(Ctrl())
    ok, reason, new = validate_updates(old, [("eso_smc.epsilon", -1.0)])
    assert not ok and new is old
    assert "eso_smc.epsilon" in reason and "(0, inf" in reason and "-1" in reason


def test_bad_choice_is_refused_listing_the_choices():
    old = validate(Ctrl())
    ok, reason, new = validate_updates(old, [("algorithm", "bang_bang")])
    assert not ok and new is old
    assert "algorithm" in reason and "pid, ladrc, eso_smc" in reason


def test_set_is_validated_as_a_whole():
    old = validate(Ctrl(eso_smc=Eso(omega_0=25.0, h=0.001)))
    # omega_0 = 600 rad/s needs h < 0.5/600 s: refused alone, accepted with h in the same set
    ok, reason, new = validate_updates(old, [("eso_smc.omega_0", 600.0)])
    assert not ok and "omega_0" in reason and "0.5" in reason and new is old
    ok, _, new = validate_updates(old, [("eso_smc.omega_0", 600.0), ("eso_smc.h", 0.0005)])
    assert ok and (new.eso_smc.omega_0, new.eso_smc.h) == (600.0, 0.0005)
    # two individually valid values refused together, nothing half-applied
    ok, reason, new = validate_updates(
        old, [("eso_smc.epsilon", 900.0), ("eso_smc.omega_0", 600.0)]
    )
    assert not ok and new is old and new.eso_smc.epsilon == 1200.0


def test_read_only_refused_live_but_accepted_at_startup():
    old = validate(Ctrl())
    ok, reason, new = validate_updates(old, [("period_s", 0.002)])
    assert not ok and "period_s" in reason and "read-only" in reason and new is old
    ok, _, new = validate_updates(old, [("period_s", 0.002)], startup=True)
    assert ok and new.period_s == 0.002
    ok, _, new = validate_updates(old, [("period_s", 0.001)])  # unchanged value is fine
    assert ok


def test_unknown_names_are_ignored_not_refused():
    old = validate(Ctrl())
    ok, _, new = validate_updates(old, [("use_sim_time", True), ("n_avg", 8)])
    assert ok and new.n_avg == 8
    ok, _, new = validate_updates(old, [("use_sim_time", True)])
    assert ok and new is old


def test_wrong_type_refused():
    old = validate(Ctrl())
    ok, reason, new = validate_updates(old, [("n_avg", 2.5)])
    assert not ok and "n_avg" in reason and new is old


def test_allowed_text_and_overrides_roundtrip():
    specs = specs_by_name(Ctrl)
    assert allowed_text(specs["enabled"]) == "true or false"
    params = validate(Ctrl())
    over = values_to_overrides(params)
    assert over["table"] == [0.0, 1.0]
    ok, _, again = validate_updates(params, list(over.items()))
    assert ok and again == params
