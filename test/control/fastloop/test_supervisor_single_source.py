"""The compiled loop's supervisor holds no copy of a safety rule: it only calls pneu_driver's.

Read from the source (ast) of :mod:`pneu_control.fastloop.supervisor`: no ordering
comparison, no arithmetic, no float constant, no ``math``; the sample and command
values reach only calls of :mod:`pneu_driver.safety.rules`, and every rule the
Python supervisor decides with is among those calls. That the rules give the same
decisions compiled and in Python: test/driver/safety/test_rules.py; that the
compiled loop matches the Python runner: test/control/experiment/test_compiled.py.
"""

from __future__ import annotations

import ast
import inspect

from pneu_control.fastloop import supervisor as adapter
from pneu_driver.safety import supervisor as python_supervisor

TREE = ast.parse(inspect.getsource(adapter))
FUNCS = {n.name: n for n in TREE.body if isinstance(n, ast.FunctionDef)}
INPUTS = {"now", "p1", "p2", "pm", "x", "c", "volts", "u", "stamp"}  # what the loop passes in
BIT_OPS = (ast.BitOr, ast.BitAnd, ast.LShift)


def _rules_calls(tree: ast.AST) -> set[str]:
    return {
        n.func.attr
        for n in ast.walk(tree)
        if isinstance(n, ast.Call)
        and isinstance(n.func, ast.Attribute)
        and isinstance(n.func.value, ast.Name)
        and n.func.value.id == "rules"
    }


def _parents(tree: ast.AST) -> dict[ast.AST, ast.AST]:
    return {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}


def test_no_comparison_arithmetic_or_constant_of_a_rule():
    for node in ast.walk(TREE):
        if isinstance(node, ast.Compare):
            assert all(isinstance(op, ast.NotEq) for op in node.ops), ast.unparse(node)
        if isinstance(node, (ast.BinOp, ast.AugAssign)):
            assert isinstance(node.op, BIT_OPS), ast.unparse(node)
        if isinstance(node, ast.Constant):
            assert not isinstance(node.value, float), ast.unparse(node)
        if isinstance(node, ast.Name):
            assert node.id != "math"
    # the only != compares a group's key mask with its last one (a change is an event)
    compares = [n for n in ast.walk(TREE) if isinstance(n, ast.Compare)]
    assert [ast.unparse(n) for n in compares] == ["keys != sn[slot]"]


def test_the_inputs_reach_only_the_rules():
    parents = _parents(TREE)
    for name in ("sup_check_sample", "sup_command", "sup_outputs"):
        fn = FUNCS[name]
        for node in ast.walk(fn):
            if isinstance(node, ast.Name) and node.id in INPUTS:
                call = parents[node]
                assert isinstance(call, ast.Call) and _rules_calls(call), (name, node.id)


def test_every_decision_of_the_python_supervisor_is_called_here():
    py = _rules_calls(ast.parse(inspect.getsource(python_supervisor)))
    # not here: the non-finite fields (the loop stops first), the encoder bound as a number
    # for a report, and deriving the thresholds (packed from the supervisor's own)
    assert py - _rules_calls(TREE) == {"non_finite_fields", "jump_allowance", "thresholds"}
    assert {
        "sample_faults", "command", "watchdog_faults", "late_faults", "update_zone", "output_v"
    } <= py  # fmt: skip
