"""The start-up grasp check: per-contact findings, its tolerance, the paper's grasp passes."""

from __future__ import annotations

import numpy as np
import pytest

from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.model.grasp_check import (
    check_grasp,
    GAP_TOLERANCE,
    grasp_findings,
    load_initial_grasp,
)
from grasp_safety_filter.model.grasp_model import GraspConfigError
from grasp_safety_filter.model.surfaces import cube_face


@pytest.fixture(scope='module')
def paper():
    model, params = load_initial_grasp(config_path())
    return (
        model,
        np.array(params['initial.joint_positions']),
        np.array(params['initial.object_position']),
    )


def test_the_papers_initial_grasp_has_no_finding(paper):
    model, q, p = paper
    assert grasp_findings(model, q, p, np.eye(3)) == []
    penetrations = [g.penetration for g in model.contact_geometry(q, p, np.eye(3))]
    assert max(abs(x) for x in penetrations) < 1e-12


@pytest.mark.parametrize(
    ('shift', 'found'), [(0.9 * GAP_TOLERANCE, False), (1.1 * GAP_TOLERANCE, True)]
)
def test_a_gap_counts_from_the_documented_tolerance(paper, shift, found):
    model, q, p = paper
    # Along x: finger1 (face -x) loses contact by `shift`, finger2 (face +x) penetrates.
    findings = grasp_findings(model, q, p + np.array([shift, 0.0, 0.0]), np.eye(3))
    subjects = [finding.subject for finding in findings]
    assert subjects == (["contact 'finger1'", "contact 'finger2'"] if found else [])


def test_each_finding_names_its_contact_and_distance(paper):
    model, q, p = paper
    findings = grasp_findings(model, q, p + np.array([0.0, 0.0, 0.2]), np.eye(3))
    edges = [f for f in findings if 'beyond the edge' in f.problem]
    assert [f.subject for f in edges] == [f"contact '{n}'" for n in model.contact_names]
    for finding in edges:
        # 0.2 m down the face from its centre: 0.2 - 0.1302 m beyond its edge.
        assert '0.0698 m' in finding.problem
    # The fingertips are now nearer the cube's bottom face than their declared faces.
    faces = [f for f in findings if f not in edges]
    assert [f.subject for f in faces] == [f"contact '{n}'" for n in model.contact_names]
    assert all("nearest face '-z'" in f.problem for f in faces)
    with pytest.raises(GraspConfigError, match=r"contact 'finger3'.*0\.0698 m"):
        check_grasp(model, q, p + np.array([0.0, 0.0, 0.2]), np.eye(3))


def test_joint_findings_come_first_and_name_the_joint(paper):
    model, q, p = paper
    q = q.copy()
    q[4] = model.joint_upper_limits[4] + 0.01
    findings = grasp_findings(model, q, p, np.eye(3))
    assert findings[0].subject == "joint 'finger2_joint2'"


def test_a_face_knows_its_edges():
    face = cube_face('+y', 0.2)
    assert face.outside_distance(np.array([0.1, -0.05])) == pytest.approx(0.0)
    assert face.outside_distance(np.array([0.0, -0.13])) == pytest.approx(0.03)
    assert face.outside_distance(np.array([0.02, 0.01])) < 0.0
