"""The parametric patient: anthropometrics from the profile, joints, validation."""

import math

import mujoco
import numpy as np
import pytest

from rehabbot.sim import PatientProfile, build_scene
from rehabbot.sim import patient as pt

PROFILES = [PatientProfile(), PatientProfile(1.62, 58.0, "female"), PatientProfile(1.98, 120.0)]
# Proximal joint body -> the body at its distal joint centre (segment length = their distance).
LIMB_ENDS = {"upper_arm": "forearm", "forearm": "hand", "thigh": "shank", "shank": "foot"}


def _patient_bodies(model):
    return [b for b in range(model.nbody)
            if any(model.geom_contype[g] == pt.CONTYPE_PATIENT
                   for g in range(model.ngeom) if model.geom_bodyid[g] == b)]


@pytest.mark.parametrize("profile", PROFILES, ids=lambda p: f"{p.sex}-{p.height_m}-{p.mass_kg}")
def test_patient_mass_equals_profile_mass(profile):
    scene = build_scene("upper_right", profile)
    total = sum(scene.model.body_mass[b] for b in _patient_bodies(scene.model))
    assert total == pytest.approx(profile.mass_kg, rel=0.01)


@pytest.mark.parametrize("profile", PROFILES, ids=lambda p: f"{p.sex}-{p.height_m}-{p.mass_kg}")
def test_segment_masses_and_lengths_match_de_leva(profile):
    scene = build_scene("upper_bilateral", profile)
    model = scene.model
    data = scene.make_data()
    scale = profile.height_m / pt.REFERENCE_STATURE_M[profile.sex]
    for name in pt.LIMB_SEGMENTS:
        row = pt.DE_LEVA[profile.sex][name]
        for side in ("r", "l"):
            body = model.body(f"{name}_{side}")
            assert body.mass[0] == pytest.approx(row.mass_fraction * profile.mass_kg, rel=0.01)
            if name in LIMB_ENDS:
                distal = model.body(f"{LIMB_ENDS[name]}_{side}").id
                length = np.linalg.norm(data.xpos[distal] - data.xpos[body.id])
                assert length == pytest.approx(row.length_ref_m * scale, rel=0.01)


def test_de_leva_mass_fractions_sum_to_one():
    for sex in pt.SEXES:
        assert pt.mass_fractions_total(sex) == pytest.approx(1.0, abs=2e-4)


def test_inertia_follows_the_radii_of_gyration():
    profile = PatientProfile()
    scene = build_scene("upper_right", profile)
    forearm = pt.segment_table(profile)["forearm"]
    inertia = scene.model.body("forearm_r").inertia
    sag, trans, lon = forearm.radius_of_gyration_m
    np.testing.assert_allclose(sorted(inertia), sorted(forearm.mass_kg * np.square([sag, trans,
                                                                                    lon])),
                               rtol=1e-9)


def test_patient_has_the_humanoid_topology():
    assert len(pt.JOINTS) == 21
    counts = {"abdomen": 3, "hip": 6, "knee": 2, "ankle": 4, "shoulder": 4, "elbow": 2}
    for prefix, n in counts.items():
        assert sum(j.name.startswith(prefix) for j in pt.JOINTS) == n


def test_positive_angles_are_the_clinical_directions():
    scene = build_scene("upper_bilateral")
    model = scene.model
    data = mujoco.MjData(model)

    def hand_offset(joint, angle_deg, body):
        data.qpos[:] = scene.home_qpos
        data.qpos[scene.patient_qpos_adr] = 0.0
        mujoco.mj_kinematics(model, data)
        before = data.xpos[model.body(body).id].copy()
        data.qpos[model.joint(joint).qposadr[0]] = math.radians(angle_deg)
        mujoco.mj_kinematics(model, data)
        return data.xpos[model.body(body).id] - before

    # Seated patient faces +x, left is +y.
    assert hand_offset("shoulder_flexion_r", 60, "hand_r")[0] > 0.3  # forward
    assert hand_offset("shoulder_abduction_r", 60, "hand_r")[1] < -0.3  # right arm out to -y
    assert hand_offset("shoulder_abduction_l", 60, "hand_l")[1] > 0.3  # left arm out to +y
    assert hand_offset("elbow_flexion_l", 90, "hand_l")[0] > 0.2  # forearm comes forward


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"height_m": 0.3}, "height_m"),
        ({"height_m": float("nan")}, "height_m"),
        ({"mass_kg": -70.0}, "mass_kg"),
        ({"mass_kg": 500.0}, "mass_kg"),
        ({"sex": "unknown"}, "sex"),
        ({"height_m": "tall"}, "height_m"),
    ],
)
def test_invalid_profile_raises_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field) as excinfo:
        PatientProfile(**kwargs)
    message = str(excinfo.value)
    if field != "sex":
        assert "[" in message and "]" in message  # the allowed range is stated
    else:
        assert "male" in message and "female" in message
