"""The graph's SROS2 keystore: one enclave per role, permissions from the topic table (sros2 shell).

``pneu security KEYSTORE [--operator NAME ...]`` calls :func:`create`: the keystore
(its identity and permissions CAs, the governance: authentication, access control
and encryption on), one enclave per role of
:data:`pneu_msgs_py.contract.security.ROLES` and per operator, each enclave's
permissions signed from :func:`~pneu_msgs_py.contract.security.policy_xml` (kept in
``KEYSTORE/pneu_policy.xml``). Permissions are bound to the domain in
``ROS_DOMAIN_ID`` (as ``ros2 security`` binds them). DESIGN §13.
"""

from __future__ import annotations

import os
import pathlib

from sros2.keystore import create_enclave, create_keystore, create_permission, is_valid_keystore

from pneu_msgs_py.contract.security import ROLES, enclave, operator_enclave, policy_xml

__all__ = ["create", "POLICY_NAME"]


def _curve_instances() -> None:
    """sros2 (Jazzy) passes the curve *class* ``ec.SECP256R1`` to ``ec.generate_private_key``;
    cryptography >= 43 wants an instance ("curve must be an EllipticCurve instance"). Give it
    one (sros2._utilities calls ``ec.generate_private_key`` through the module attribute)."""
    from cryptography.hazmat.primitives.asymmetric import ec

    original = ec.generate_private_key
    if getattr(original, "_pneu_shim", False):
        return

    def generate_private_key(curve, *args, **kwargs):
        return original(curve() if isinstance(curve, type) else curve, *args, **kwargs)

    generate_private_key._pneu_shim = True  # type: ignore[attr-defined]
    ec.generate_private_key = generate_private_key


POLICY_NAME = "pneu_policy.xml"


def create(keystore: pathlib.Path, operators: tuple[str, ...] = ()) -> list[str]:
    """Create (or complete) ``keystore`` for the graph and ``operators``; the enclaves made.

    An existing keystore keeps its CAs and enclaves' keys (so running nodes keep
    working); every enclave's permissions are signed again from today's policy.
    """
    _curve_instances()
    keystore = pathlib.Path(keystore)
    paths = [enclave(r) for r in ROLES] + [operator_enclave(n) for n in operators]
    text = policy_xml(tuple(operators))
    if not is_valid_keystore(keystore):
        create_keystore(keystore)
    policy = keystore / POLICY_NAME
    tmp = keystore / (POLICY_NAME + ".partial")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, policy)
    for path in paths:
        create_enclave(keystore, path)  # a wildcard permission sros2 writes first ...
        create_permission(keystore, path, policy)  # ... replaced by the policy's
    return paths
