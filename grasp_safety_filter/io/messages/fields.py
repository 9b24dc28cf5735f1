"""Field-level conversion and validation: frames, times, names, vectors, rotations, clock."""

from __future__ import annotations

import array as array_module  # rclpy's float fields
from collections import Counter
from collections.abc import Sequence
from functools import lru_cache
import math
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages.errors import (
    bounded_text,
    MAX_NAME_TEXT,
    MessageError,
    name_list,
)
from grasp_safety_filter.io.messages.namespace import MessageNamespace
from grasp_safety_filter.model.quaternion import from_rotation_matrix, rotation_matrix

#: Default frame names of the message functions: the paper's hand's palm (its URDF's root
#: link) and the object. A model names its own (``GraspModel.palm_frame``, ``object_frame``:
#: ``model.palm_frame``, ``model.object_frame``), and the endpoints pass those.
PALM_FRAME = 'palm'
OBJECT_FRAME = 'object'


_QUATERNION_NORM_TOLERANCE = 1e-6
_ROTATION_TOLERANCE = 1e-6
# ----------------------------------------------------------------------------------------
# Validation helpers


def check_frame(source: str, what: str, received: str, expected: str) -> None:
    """Raise :class:`MessageError` naming ``source``, ``what`` unless the frame is ``expected``."""
    if received != expected:
        got = bounded_text(repr(received), MAX_NAME_TEXT)
        raise MessageError(f'{source}: {what} must be {expected!r}, got {got}')


def unique_names(source: str, names: Sequence[str], kind: str) -> tuple[str, ...]:
    """:func:`checked_names` as a tuple, checked once per name tuple (a producer's names)."""
    return _unique_names(source, tuple(names), kind)


@lru_cache(maxsize=64)
def _unique_names(source: str, names: tuple[str, ...], kind: str) -> tuple[str, ...]:
    return tuple(checked_names(source, names, kind))


def checked_names(source: str, names: Sequence[str], kind: str) -> list[str]:
    """Received names as a list; raise on duplicates."""
    received = [str(n) for n in names]
    if len(set(received)) == len(received):
        return received
    duplicates = sorted(n for n, count in Counter(received).items() if count > 1)
    if duplicates:
        raise MessageError(
            f'{source}: {len(duplicates)} duplicate {kind} names {name_list(duplicates)}'
        )
    return received


#: Name lists already matched: ``{(received, expected): index}`` (see :func:`match_names`).
_MATCHED: dict[tuple[tuple[str, ...], tuple[str, ...], bool], np.ndarray] = {}
#: Most name lists remembered (a stream sends one or two; the cache is emptied when full).
_MAX_MATCHED = 256


def match_names(
    source: str,
    received_names: Sequence[str],
    expected_names: Sequence[str],
    kind: str,
    *,
    others: bool = False,
) -> np.ndarray:
    """Index of each expected name in the received names (any order, each exactly once).

    ``others``: received names that are not expected are ignored (else refused). Every
    stream sends the same names again and again: a pair of name lists that matched once
    gives the same (read-only) index without checking again; one that did not is checked,
    and refused, every time.
    """
    key = (tuple(map(str, received_names)), tuple(expected_names), others)
    index = _MATCHED.get(key)
    if index is None:
        index = _match_names(source, list(key[0]), expected_names, kind, others)
        index.flags.writeable = False
        if len(_MATCHED) >= _MAX_MATCHED:
            _MATCHED.clear()
        _MATCHED[key] = index
    return index


def other_names(received_names: Sequence[str], expected_names: Sequence[str]) -> list[str]:
    """Return the received names that are not expected, in received order."""
    expected = set(expected_names)
    return [str(name) for name in received_names if name not in expected]


def _match_names(
    source: str,
    received_names: Sequence[str],
    expected_names: Sequence[str],
    kind: str,
    others: bool = False,
) -> np.ndarray:
    """:func:`match_names` without the memory of name lists already matched."""
    received = checked_names(source, received_names, kind)
    index = {name: i for i, name in enumerate(received)}
    unknown = other_names(received, expected_names)
    if unknown and not others:
        raise MessageError(
            f'{source}: {len(unknown)} unknown {kind} names {name_list(unknown)}; expected '
            f'{list(expected_names)}'
        )
    missing = [n for n in expected_names if n not in index]
    if missing:
        raise MessageError(
            f'{source}: missing {kind} names {missing}; received {len(received)} '
            f'{name_list(received)}'
        )
    return np.array([index[n] for n in expected_names], dtype=int)


def _is_empty(values: Any) -> bool:
    """Whether ``values`` is a message's empty float field (a list, array or tuple)."""
    return isinstance(values, (list, tuple, np.ndarray, array_module.array)) and len(values) == 0


def array_field(
    source: str,
    values: Any,
    field_name: str,
    names: Sequence[str],
    *,
    required: bool,
    allow_positive_inf: Sequence[bool] | None = None,
) -> np.ndarray | None:
    """Return a float field with one finite entry per name; ``None`` if optional and empty.

    Args:
        source: Name used in error messages.
        values: The field's values.
        field_name: The field's name.
        names: The message's names.
        required: The field must have one entry per name (else it may also be empty).
        allow_positive_inf: Per name, whether ``+inf`` is admissible there.

    """
    if not required and _is_empty(values):  # an empty optional field: nothing to check
        return None
    array = np.asarray(values, dtype=np.float64)
    if array.ndim != 1:
        array = array.ravel()
    if array.size == 0 and not required:
        return None
    if array.size != len(names):
        expectation = 'one entry per name' if required else 'none or one entry per name'
        raise MessageError(
            f"{source}: '{field_name}' has {array.size} entries, expected {expectation} "
            f'({len(names)})'
        )
    # Not a sum of the entries: NaN, inf or an overflowing sum would warn in a validator.
    finite = np.isfinite(array)
    if finite.all():
        return array
    bad = ~finite
    if allow_positive_inf is not None:
        bad &= ~(np.asarray(allow_positive_inf, dtype=bool) & (array == np.inf))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        name = bounded_text(str(names[i]), MAX_NAME_TEXT)
        raise MessageError(f"{source}: '{field_name}' of '{name}' is {float(array[i])!r}")
    return array


def finite_vector(source: str, what: str, values: Sequence[float]) -> np.ndarray:
    """Return ``values`` as a float64 array; raise :class:`MessageError` if one is not finite."""
    floats = [float(v) for v in values]
    if not all(map(math.isfinite, floats)):  # a few numbers: cheaper than numpy's
        raise MessageError(f'{source}: {what} must be finite, got {floats}')
    return np.array(floats, dtype=np.float64)


def unit_quaternion(source: str, what: str, msg: Any) -> np.ndarray:
    """Return a ``geometry_msgs/Quaternion`` as finite ``(x, y, z, w)`` of unit norm, or raise."""
    quaternion = finite_vector(source, what, (msg.x, msg.y, msg.z, msg.w))
    if float(np.abs(quaternion).max()) > 2.0:
        # Far from unit (up to 1e308): hypot's norm cannot overflow, numpy's would warn.
        norm = math.hypot(*quaternion)
    else:
        norm = float(np.linalg.norm(quaternion))
    if abs(norm - 1.0) > _QUATERNION_NORM_TOLERANCE:
        raise MessageError(
            f'{source}: {what} must be a unit quaternion (|norm - 1| <= '
            f'{_QUATERNION_NORM_TOLERANCE}), got norm {norm!r}'
        )
    return quaternion / norm


def shaped_array(what: str, values: Any, shape: tuple[int, ...]) -> np.ndarray:
    """Return ``values`` as a float64 array of ``shape``, or raise :class:`MessageError`."""
    array = np.asarray(values, dtype=np.float64)
    if array.shape != shape:
        raise MessageError(f'{what}: expected shape {shape}, got {array.shape}')
    return array


# ----------------------------------------------------------------------------------------
# Rotations


def quaternion_xyzw_from_matrix(R: np.ndarray) -> np.ndarray:
    """Return the unit quaternion ``(x, y, z, w)``, ``w >= 0``, of a rotation matrix.

    Raises:
        MessageError: ``R`` is not 3x3 or not a rotation within 1e-6.

    """
    R = shaped_array('rotation matrix', R, (3, 3))
    entries = R.tolist()
    if not all(map(math.isfinite, entries[0] + entries[1] + entries[2])):
        raise MessageError(f'rotation matrix: expected finite entries, got {entries}')
    error, det = _orthonormality(entries)
    if error > _ROTATION_TOLERANCE or det < 0.0:
        raise MessageError(
            f'rotation matrix: expected orthonormal with det +1 (within '
            f'{_ROTATION_TOLERANCE}), got |R^T R - I| = {error:.3g}, det {det:.6g}'
        )
    return from_rotation_matrix(R)


def _orthonormality(entries: list[list[float]]) -> tuple[float, float]:
    """Return ``max |R^T R - I|`` and ``det R`` of a 3x3 matrix given as rows of floats.

    Written out on Python floats: for one 3x3 matrix a message, numpy's calls cost more
    than the arithmetic (``(R^T R)_jk`` is the dot product of columns j and k).
    """
    (a, b, c), (d, e, f), (g, h, i) = entries
    error = max(
        abs(a * a + d * d + g * g - 1.0),
        abs(b * b + e * e + h * h - 1.0),
        abs(c * c + f * f + i * i - 1.0),
        abs(a * b + d * e + g * h),
        abs(a * c + d * f + g * i),
        abs(b * c + e * f + h * i),
    )
    det = a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
    return error, det


def matrix_from_quaternion_xyzw(quaternion: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion ``(x, y, z, w)`` (normalised first)."""
    return rotation_matrix(quaternion)


def quaternion_msg(msgs: MessageNamespace, R: np.ndarray) -> Any:
    """Build a ``geometry_msgs/Quaternion`` of the rotation matrix ``R``."""
    x, y, z, w = quaternion_xyzw_from_matrix(R).tolist()
    return msgs.Quaternion(x=x, y=y, z=z, w=w)


def vector3_msg(msgs: MessageNamespace, v: np.ndarray) -> Any:
    """Build a ``geometry_msgs/Vector3`` of ``v``, shape (3,)."""
    return msgs.Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def twist_msg(msgs: MessageNamespace, twist: np.ndarray) -> Any:
    """Build a ``geometry_msgs/Twist`` of ``(v, w)``, shape (6,)."""
    vx, vy, vz, wx, wy, wz = np.asarray(twist, dtype=np.float64).tolist()
    return msgs.Twist(
        linear=msgs.Vector3(x=vx, y=vy, z=vz), angular=msgs.Vector3(x=wx, y=wy, z=wz)
    )


def twist_from_msg(source: str, what: str, msg: Any) -> np.ndarray:
    """Return a ``geometry_msgs/Twist`` as finite ``(v, w)``, shape (6,), or raise."""
    return finite_vector(
        source,
        what,
        (msg.linear.x, msg.linear.y, msg.linear.z, msg.angular.x, msg.angular.y, msg.angular.z),
    )
