"""Unit conversions used only at the edges (reports, CLI, controller gains).

Inside pneu everything is SI: m, Pa (absolute), rad, rad/s, V, s.
"""

from __future__ import annotations

import math

__all__ = [
    "MM_PER_M",
    "RPM_PER_RAD_S",
    "DEG_PER_RAD",
    "P_ATM_PA",
    "rpm_to_rad_s",
    "rad_s_to_rpm",
    "m_to_mm",
    "mm_to_m",
    "mpa_gauge_to_pa_abs",
]

MM_PER_M = 1000.0
RPM_PER_RAD_S = 60.0 / (2.0 * math.pi)  # 1 rad/s = 9.549 rpm
DEG_PER_RAD = 180.0 / math.pi  # rotary angle control: references and gains in degrees
P_ATM_PA = 101325.0  # standard atmosphere, ISO 2533


def rpm_to_rad_s(n_rpm: float) -> float:
    return n_rpm / RPM_PER_RAD_S


def rad_s_to_rpm(omega_rad_s: float) -> float:
    return omega_rad_s * RPM_PER_RAD_S


def m_to_mm(x_m: float) -> float:
    return x_m * MM_PER_M


def mm_to_m(x_mm: float) -> float:
    return x_mm / MM_PER_M


def mpa_gauge_to_pa_abs(p_mpa_gauge: float, p_atm_pa: float = P_ATM_PA) -> float:
    return p_mpa_gauge * 1e6 + p_atm_pa
