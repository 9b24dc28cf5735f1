"""``/object/reference`` is bounded in size and its active point is found by bisection."""

import bisect
import math

import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io.messages import (
    MAX_REFERENCE_POINTS,
    MessageError,
    MessageNamespace,
    ObjectReference,
)
from grasp_safety_filter.io.topics import OBJECT_REFERENCE

MSGS = MessageNamespace.from_typestore(get_typestore(Stores.ROS2_JAZZY))
POINT = ObjectReference(np.zeros(3), np.eye(3), np.zeros(6), np.zeros(6))


def reference(k: int):
    """Return a reference message of ``k`` points, one every 10 ms."""
    return m.reference_to_msg(MSGS, 2.0, [0.01 * i for i in range(k)], [POINT] * k)


def test_the_bound_is_accepted():
    trajectory = m.reference_from_msg(reference(MAX_REFERENCE_POINTS))
    assert len(trajectory.points) == MAX_REFERENCE_POINTS


@pytest.mark.parametrize('k', [MAX_REFERENCE_POINTS + 1, 100_000])
def test_a_longer_reference_is_refused_naming_topic_count_and_bound(k):
    msg = reference(1)
    msg.points[0].transforms[0].translation.x = math.nan  # would be reported if read
    msg.points = msg.points * k
    with pytest.raises(MessageError) as caught:
        m.reference_from_msg(msg, source=OBJECT_REFERENCE)
    text = str(caught.value)
    assert text.startswith(f'{OBJECT_REFERENCE}: ')
    assert f'at most {MAX_REFERENCE_POINTS} points' in text
    assert f'got {k}' in text
    assert 'nan' not in text  # refused before any point is parsed


def test_the_active_point_is_the_last_one_started():
    trajectory = m.reference_from_msg(reference(MAX_REFERENCE_POINTS))
    times = list(trajectory.time_from_start)
    for t in np.linspace(0.0, 13.0, 2_000):
        expected = max(bisect.bisect_right(times, t - 2.0) - 1, 0)
        assert trajectory.active_index(float(t)) == expected
