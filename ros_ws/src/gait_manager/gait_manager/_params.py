"""Validation helpers shared by the parameter dataclasses of gait_manager (private).

Every helper raises ``GaitManagerError`` with a message that starts with the key's name.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import fields
import math
import numbers
from typing import Any, TypeVar

import numpy as np

from gait_manager.errors import GaitManagerError

N_COORDINATES = 18
T = TypeVar('T')


def real(name: str, value: Any, low: float | None = None, high: float | None = None,
         open_low: bool = False) -> float:
    """Return ``value`` as a finite float in [low, high] (or (low, high] if ``open_low``)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise GaitManagerError(f'{name} must be a number, got {value!r}')
    x = float(value)
    if not math.isfinite(x):
        raise GaitManagerError(f'{name} must be finite, got {value!r}')
    if low is not None and (x < low or (open_low and x == low)):
        raise GaitManagerError(f'{name} must be {">" if open_low else ">="} {low}, got {value!r}')
    if high is not None and x > high:
        raise GaitManagerError(f'{name} must be <= {high}, got {value!r}')
    return x


def integer(name: str, value: Any, low: int | None = None) -> int:
    """Return ``value`` as an int >= ``low`` (bools are rejected)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise GaitManagerError(f'{name} must be an integer, got {value!r}')
    if low is not None and value < low:
        raise GaitManagerError(f'{name} must be >= {low}, got {value!r}')
    return int(value)


def boolean(name: str, value: Any) -> bool:
    """Return ``value`` if it is a bool."""
    if not isinstance(value, bool):
        raise GaitManagerError(f'{name} must be true or false, got {value!r}')
    return value


def choice(name: str, value: Any, options: Sequence[str]) -> str:
    """Return ``value`` if it is one of ``options``."""
    if not isinstance(value, str) or value not in options:
        raise GaitManagerError(f'{name} must be one of {tuple(options)}, got {value!r}')
    return value


def joints(name: str, value: Any, low: int = 1, high: int = 17) -> tuple[int, ...]:
    """Return a tuple of distinct joint numbers in [low, high]."""
    if isinstance(value, (str, bytes)) or not isinstance(value, (Sequence, frozenset, set)):
        raise GaitManagerError(f'{name} must be a list of joint numbers, got {value!r}')
    out = []
    for j in value:
        if isinstance(j, bool) or not isinstance(j, numbers.Integral) or not low <= j <= high:
            raise GaitManagerError(f'{name} entries must be integers in {low}..{high}, got {j!r}')
        out.append(int(j))
    if len(set(out)) != len(out):
        raise GaitManagerError(f'{name} must not repeat a joint, got {out}')
    return tuple(out)


def build(cls: type[T], d: Any, prefix: str) -> T:
    """Construct dataclass ``cls`` from mapping ``d``; unknown keys raise. Messages of errors
    raised by the constructor get ``prefix`` (e.g. 'posture.') in front of the key name."""
    if isinstance(d, cls):
        return d
    if not isinstance(d, Mapping):
        raise GaitManagerError(f'{prefix.rstrip(".") or "parameters"} must be a mapping, '
                               f'got {d!r}')
    known = [f.name for f in fields(cls)]  # type: ignore[arg-type]
    for key in d:
        if key not in known:
            raise GaitManagerError(f'unknown key {prefix}{key!s}; expected one of {known}')
    try:
        return cls(**dict(d))
    except GaitManagerError as exc:
        raise GaitManagerError(f'{prefix}{exc}') from None


def smoothstep(x: float) -> float:
    """3x^2 - 2x^3 on [0, 1], clamped outside."""
    x = min(max(x, 0.0), 1.0)
    return x * x * (3.0 - 2.0 * x)


def zeros() -> np.ndarray:
    """A fresh 18-vector of zeros (one entry per coordinate [y0, q1..q17])."""
    return np.zeros(N_COORDINATES)


def phase(reading: str, t: float, t_exchange: float, period: float) -> float:
    """Phase Phi [rad] of eq. (10): 'A' 2(t - t_e)/T (literal), 'B' 2 pi (t - t_e)/T,
    'B_clipped' reading B clipped to [0, pi] (model-spec §7.4)."""
    dt = t - t_exchange
    if reading == 'A':
        return 2.0 * dt / period
    phi = 2.0 * math.pi * dt / period
    if reading == 'B_clipped':
        return min(max(phi, 0.0), math.pi)
    return phi


PHASE_READINGS = ('A', 'B', 'B_clipped')
