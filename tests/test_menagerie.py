"""Optional Menagerie meshes, tested against a fake Menagerie written to ``tmp_path``.

The fake is a UR5e-shaped chain with the Menagerie's body, joint and site names, generated from
a DH table but with other body frames than ours (every body rotated and shifted by a fixed
offset, the whole robot under a base turned 180° about z), visual mesh geoms in a ``visual``
class and a collision class, like the real ``universal_robots_ur5e/ur5e.xml``. No real
Menagerie is needed and nothing is downloaded.
"""

from __future__ import annotations

import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np
import pytest

from rehabbot.sim import build_scene
from rehabbot.sim.robots import menagerie as mg
from rehabbot.sim.robots import parts
from rehabbot.sim.robots import ur5e as ur

MENAGERIE_BODIES = [men for _, men in mg.BODY_MAP]
# The real Menagerie rounds the UR5e's link lengths to the millimetre.
ROUNDED_A_M = np.array([0.0, -0.425, -0.392, 0.0, 0.0, 0.0])
ROUNDED_D_M = np.array([0.163, 0.0, 0.0, 0.134, 0.1, 0.1])

# Fixed offsets of the fake's body frames from DH frames 0..6: (quaternion, translation [m]).
_BODY_OFFSETS = [
    ((0.3, 0.1, -0.5, 0.8), (0.01, -0.02, 0.03)),
    ((1.0, 0.0, 1.0, 0.0), (0.0, 0.05, -0.01)),
    ((0.2, 0.9, -0.3, 0.1), (-0.03, 0.0, 0.07)),
    ((1.0, 1.0, 0.0, 0.0), (0.1, 0.0, 0.0)),
    ((0.5, -0.5, 0.5, 0.5), (0.0, 0.0, -0.04)),
    ((0.0, 0.0, 0.0, 1.0), (0.02, 0.02, 0.02)),
    ((0.7, 0.0, 0.3, -0.6), (0.0, -0.01, 0.05)),
]
# Visual geoms per fake body: (mesh, material, pos, orientation attribute, inside a <frame>).
_VISUALS = {
    0: [("tet", "black", (0.01, 0.0, 0.02), 'quat="0.9 0.1 0.2 0.3"', False),
        ("wedge", "urblue", (0.0, 0.03, 0.0), 'euler="0.3 -0.2 1.1"', False)],
    1: [("wedge", "urblue", (0.02, -0.01, 0.0), 'axisangle="0 1 1 0.7"', False)],
    2: [("tet", "linkgray", (0.1, 0.0, 0.05), 'quat="1 0 0 0"', False),
        ("wedge", "black", (0.0, 0.0, 0.2), 'quat="0.5 0.5 -0.5 0.5"', True)],
    3: [("tet", "linkgray", (-0.05, 0.02, 0.1), 'euler="1 2 3"', False)],
    4: [("wedge", "urblue", (0.0, 0.0, 0.0), 'quat="1 0 0 0"', True)],
    5: [("tet", "black", (0.01, 0.02, 0.03), 'quat="0 1 0 0"', False)],
    6: [("tet", "linkgray", (0.0, 0.0, 0.01), 'zaxis="1 1 0"', False),
        ("wedge", "black", (0.03, 0.0, 0.0), 'quat="0.2 0.3 0.4 0.5"', False)],
}
N_VISUALS = sum(len(v) for v in _VISUALS.values())
_RGBA = {"black": (0.033, 0.033, 0.033, 1.0), "urblue": (0.49, 0.678, 0.8, 1.0),
         "linkgray": (0.82, 0.82, 0.82, 1.0)}
_TET_OBJ = """# a small tetrahedron, off its centroid so MuJoCo re-centres it
v 0.01 0.02 0.00
v 0.06 0.02 0.00
v 0.01 0.07 0.00
v 0.01 0.02 0.05
f 1 3 2
f 1 2 4
f 1 4 3
f 2 3 4
"""
_WEDGE_OBJ = """# a long thin tetrahedron
v 0 0 0
v 0.12 0 0
v 0 0.03 0
v 0 0 0.02
f 1 3 2
f 1 2 4
f 1 4 3
f 2 3 4
"""


def _pose(pos, quat) -> np.ndarray:
    quat = np.asarray(quat, dtype=float)
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat / np.linalg.norm(quat))
    out = np.eye(4)
    out[:3, :3] = mat.reshape(3, 3)
    out[:3, 3] = pos
    return out


def _quat(pose: np.ndarray) -> np.ndarray:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(pose[:3, :3]).ravel())
    return quat


def _fmt(values) -> str:
    return " ".join(repr(float(v)) for v in values)


def _dh_step(i: int, a_m: np.ndarray, d_m: np.ndarray) -> np.ndarray:
    """DH frame i+1 in DH frame i at zero joint angle: Tz(d) Tx(a) Rx(alpha)."""
    alpha = ur.DH_ALPHA_RAD[i]
    return _pose((a_m[i], 0.0, d_m[i]), (np.cos(alpha / 2), np.sin(alpha / 2), 0.0, 0.0))


@dataclass
class FakeMenagerie:
    root: Path
    xml: Path
    dh0_in_world: np.ndarray  # DH frame 0 (our robot base frame) in the fake's world


def write_fake_menagerie(root: Path, a_m=ur.DH_A_M, d_m=ur.DH_D_M,
                         flip_wrist_3: bool = False) -> FakeMenagerie:
    """Write ``root/universal_robots_ur5e/ur5e.xml`` and its OBJ meshes.

    Fake body i sits at ``DH_i · E_i`` (fixed offsets ``E_i``); base body at 180° about z.
    """
    folder = root / "universal_robots_ur5e"
    (folder / "assets").mkdir(parents=True, exist_ok=True)
    (folder / "assets" / "tet.obj").write_text(_TET_OBJ)
    (folder / "assets" / "wedge.obj").write_text(_WEDGE_OBJ)
    offsets = [_pose(t, q) for q, t in _BODY_OFFSETS]
    base_in_world = _pose((0.2, -0.1, 0.05), (0.0, 0.0, 0.0, 1.0))
    dh0_in_world = base_in_world @ np.linalg.inv(offsets[0])

    def visuals(i: int, indent: str) -> str:
        lines = []
        for k, (mesh, material, pos, orient, in_frame) in enumerate(_VISUALS[i]):
            geom = (f'<geom name="vis_{i}_{k}" mesh="{mesh}" material="{material}" '
                    f'class="visual" pos="{_fmt(pos)}" {orient}/>')
            if in_frame:
                geom = f'<frame pos="0.01 0.02 -0.03" euler="0.4 0 -0.2">{geom}</frame>'
            lines.append(indent + geom)
        lines.append(indent + '<geom class="collision" size="0.03 0.02" pos="0 0 0.01"/>')
        lines.append(indent + '<geom mesh="tet" type="mesh" group="3"/>')  # collision mesh
        return "\n".join(lines)

    body_xml = []
    close = []
    for i in range(1, 7):
        parent_offset = offsets[i - 1]
        child = _dh_step(i - 1, a_m, d_m) @ offsets[i]  # child body in DH frame i-1 at q = 0
        local = np.linalg.inv(parent_offset) @ child
        axis = child[:3, :3].T @ np.array([0.0, 0.0, 1.0])
        if flip_wrist_3 and i == 6:
            axis = -axis
        anchor = -child[:3, :3].T @ child[:3, 3]
        indent = "  " * (i + 3)
        body_xml.append(
            f'{indent}<body name="{MENAGERIE_BODIES[i]}" pos="{_fmt(local[:3, 3])}" '
            f'quat="{_fmt(_quat(local))}">\n'
            f'{indent}  <inertial mass="1" pos="0 0 0" diaginertia="0.01 0.01 0.01"/>\n'
            f'{indent}  <joint name="{mg.MENAGERIE_JOINTS[i - 1]}" axis="{_fmt(axis)}" '
            f'pos="{_fmt(anchor)}"/>\n'
            f'{visuals(i, indent + "  ")}')
        close.append(f"{indent}</body>")
    flange = np.linalg.inv(offsets[6])
    body_xml.append(f'{"  " * 10}<site name="attachment_site" pos="{_fmt(flange[:3, 3])}" '
                    f'quat="{_fmt(_quat(flange))}"/>')
    materials = "\n".join(f'    <material class="ur5e" name="{n}" rgba="{_fmt(c)}"/>'
                          for n, c in _RGBA.items())
    xml = f"""<mujoco model="ur5e">
  <compiler angle="radian" meshdir="assets" autolimits="true"/>
  <default>
    <default class="ur5e">
      <material specular="0.5" shininess="0.25"/>
      <joint axis="0 1 0" range="-6.28319 6.28319" armature="0.1"/>
      <default class="visual">
        <geom type="mesh" contype="0" conaffinity="0" group="2"/>
      </default>
      <default class="collision">
        <geom type="capsule" group="3"/>
      </default>
    </default>
  </default>
  <asset>
{materials}
    <mesh file="tet.obj"/>
    <mesh file="wedge.obj" scale="1.5 1 0.8"/>
  </asset>
  <worldbody>
    <light name="spot" pos="0 -1 2"/>
    <body name="base" pos="{_fmt(base_in_world[:3, 3])}" quat="0 0 0 1" childclass="ur5e">
      <inertial mass="4" pos="0 0 0" diaginertia="0.0044 0.0044 0.0072"/>
{visuals(0, "      ")}
{chr(10).join(body_xml)}
{chr(10).join(reversed(close))}
    </body>
  </worldbody>
</mujoco>
"""
    path = folder / "ur5e.xml"
    path.write_text(xml)
    return FakeMenagerie(root=root, xml=path, dh0_in_world=dh0_in_world)


@pytest.fixture(scope="module")
def fake(tmp_path_factory) -> FakeMenagerie:
    return write_fake_menagerie(tmp_path_factory.mktemp("menagerie"))


@pytest.fixture(scope="module")
def scene(fake):
    return build_scene("upper_right", menagerie_dir=str(fake.root))


def _geom_pose(data: mujoco.MjData, gid: int) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = data.geom_xmat[gid].reshape(3, 3)
    out[:3, 3] = data.geom_xpos[gid]
    return out


# ------------------------------------------------------------------------------------- tests
def test_the_fake_has_the_ur5e_kinematics(fake):
    """Guard for the fixture itself: its flange follows the DH table."""
    model = mujoco.MjModel.from_xml_path(str(fake.xml))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(1)
    for q in rng.uniform(-np.pi, np.pi, size=(5, 6)):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        flange = np.linalg.inv(fake.dh0_in_world) @ np.append(
            data.site_xpos[model.site("attachment_site").id], 1.0)
        np.testing.assert_allclose(flange[:3], ur.dh_forward_kinematics(q)[:3, 3], atol=1e-9)
    # Its body frames really differ from ours.
    data.qpos[:] = 0.0
    mujoco.mj_kinematics(model, data)
    assert not np.allclose(data.xmat[model.body("base").id], np.eye(3).ravel())


def test_find_menagerie_ur5e_accepts_root_folder_and_file(fake, tmp_path):
    for given in (fake.root, fake.root / "universal_robots_ur5e", fake.xml, str(fake.root)):
        assert mg.find_menagerie_ur5e(given) == fake.xml.resolve()
    with pytest.raises(FileNotFoundError, match=r"ur5e\.xml") as info:
        mg.find_menagerie_ur5e(tmp_path / "nowhere")
    assert "universal_robots_ur5e" in str(info.value)


def test_find_menagerie_ur5e_expands_home(fake, monkeypatch):
    monkeypatch.setenv("HOME", str(fake.root.parent))
    assert mg.find_menagerie_ur5e(f"~/{fake.root.name}") == fake.xml.resolve()


def test_scene_gets_every_visual_mesh_and_only_those(scene):
    model = scene.model
    meshes = [g for g in range(model.ngeom) if model.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH]
    assert len(meshes) == N_VISUALS
    for gid in meshes:
        assert model.geom(gid).name.startswith("menagerie_")
        assert model.geom_contype[gid] == 0 and model.geom_conaffinity[gid] == 0
        assert model.geom_group[gid] == mg.VISUAL_GROUP
    robot_bodies = {model.body(ours).id: men for ours, men in mg.BODY_MAP}
    for i, men in enumerate(MENAGERIE_BODIES):
        for k, (_, material, *_rest) in enumerate(_VISUALS[i]):
            geom = model.geom(f"menagerie_{men}_{k}")
            assert robot_bodies[model.geom_bodyid[geom.id]] == men
            np.testing.assert_allclose(geom.rgba, _RGBA[material])


def test_add_menagerie_visuals_returns_the_count_and_references_the_users_files(fake):
    spec = ur.build_ur5e_spec()
    assert mg.add_menagerie_visuals(spec, "", fake.xml) == N_VISUALS
    files = {Path(mesh.file) for mesh in spec.meshes}
    assert files == {fake.xml.parent.resolve() / "assets" / "tet.obj",
                     fake.xml.parent.resolve() / "assets" / "wedge.obj"}
    np.testing.assert_allclose(spec.mesh("menagerie_wedge").scale, [1.5, 1.0, 0.8])
    spec.compile()


def test_meshes_move_with_the_right_links(fake, scene):
    """At random joint angles, every copied mesh geom has the fake's pose, seen from the base."""
    model, handle = scene.model, scene.robots[0]
    data = scene.make_data()
    men_model = mujoco.MjModel.from_xml_path(str(fake.xml))
    men_data = mujoco.MjData(men_model)
    men_qadr = [men_model.joint(j).qposadr[0] for j in mg.MENAGERIE_JOINTS]
    world_to_dh0 = np.linalg.inv(fake.dh0_in_world)
    rng = np.random.default_rng(7)
    for q in [np.zeros(6), *rng.uniform(-np.pi, np.pi, size=(6, 6))]:
        data.qpos[handle.qpos_adr] = q
        mujoco.mj_kinematics(model, data)
        men_data.qpos[men_qadr] = q
        mujoco.mj_kinematics(men_model, men_data)
        base = np.eye(4)
        base[:3, :3] = data.xmat[handle.base_body_id].reshape(3, 3)
        base[:3, 3] = data.xpos[handle.base_body_id]
        to_base = np.linalg.inv(base)
        for i, men in enumerate(MENAGERIE_BODIES):
            for k in range(len(_VISUALS[i])):
                ours = to_base @ _geom_pose(data, model.geom(f"menagerie_{men}_{k}").id)
                theirs = world_to_dh0 @ _geom_pose(men_data, men_model.geom(f"vis_{i}_{k}").id)
                np.testing.assert_allclose(ours, theirs, atol=1e-6)


def test_own_geoms_still_collide_but_are_hidden(scene):
    model = scene.model
    own = [g for g in scene.robot_geom_ids
           if not model.geom(g).name.startswith("menagerie_")]
    assert own
    for gid in own:
        name = model.geom(gid).name
        if name in ("cuff", "cuff_bracket"):  # the strap is no part of the UR5e: still drawn
            assert model.geom_group[gid] < 3
        else:
            assert model.geom_group[gid] == mg.HIDDEN_GROUP, name
            assert model.geom_contype[gid] == parts.CONTYPE_ROBOT, name


def test_cuff_is_satisfied_at_reset(scene):
    data = scene.make_data()
    assert np.all(scene.cuff_errors_m(data) < 1e-3)


def test_physics_is_unchanged_by_the_looks(scene):
    plain = build_scene("upper_right")
    np.testing.assert_array_equal(plain.model.body_mass, scene.model.body_mass)
    np.testing.assert_allclose(plain.home_qpos, scene.home_qpos, atol=1e-12)
    np.testing.assert_allclose(plain.home_setpoints, scene.home_setpoints, atol=1e-12)


def test_bilateral_scene_gets_meshes_on_both_robots(fake):
    scene = build_scene("upper_bilateral", menagerie_dir=fake.root)
    model = scene.model
    for prefix in ("right_", "left_"):
        names = [model.geom(g).name for g in range(model.ngeom)
                 if model.geom(g).name.startswith(f"{prefix}menagerie_")]
        assert len(names) == N_VISUALS


def test_wrong_path_is_a_value_error_naming_the_option(tmp_path):
    with pytest.raises(ValueError, match="menagerie_dir"):
        build_scene("upper_right", menagerie_dir=str(tmp_path / "no_menagerie"))
    with pytest.raises(ValueError, match="menagerie_dir"):
        build_scene("upper_right", menagerie_dir=42)


def test_wrong_link_length_is_rejected(tmp_path):
    a_m = ur.DH_A_M.copy()
    a_m[2] *= 1.1  # forearm 39 mm longer
    fake = write_fake_menagerie(tmp_path, a_m=a_m)
    with pytest.raises(ValueError, match="does not match the UR5e kinematics"):
        build_scene("upper_right", menagerie_dir=fake.root)


def test_joint_turning_the_other_way_is_rejected(tmp_path):
    """Wrist 3 does not move the flange centre: the per-link frame check must catch it."""
    fake = write_fake_menagerie(tmp_path, flip_wrist_3=True)
    with pytest.raises(ValueError, match="does not match the UR5e kinematics"):
        mg.add_menagerie_visuals(ur.build_ur5e_spec(), "", str(fake.root))


def test_menagerie_rounded_link_lengths_are_accepted(tmp_path):
    """The real Menagerie rounds link lengths to the millimetre; that must still fit."""
    fake = write_fake_menagerie(tmp_path, a_m=ROUNDED_A_M, d_m=ROUNDED_D_M)
    spec = ur.build_ur5e_spec()
    mg.add_menagerie_visuals(spec, "", str(fake.root))
    model = spec.compile()
    assert sum(model.geom_type == mujoco.mjtGeom.mjGEOM_MESH) == N_VISUALS


def test_import_does_not_load_the_menagerie_module():
    code = ("import sys, rehabbot.sim\n"
            "from rehabbot.sim import build_scene\n"
            "build_scene('upper_right')\n"
            "print('rehabbot.sim.robots.menagerie' in sys.modules)\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True, timeout=120)
    assert result.stdout.strip() == "False"


def test_cli_snapshot_with_menagerie(fake, tmp_path, capsys):
    pytest.importorskip("imageio.v3", reason='snapshot tests need "rehabbot[video]"')
    from rehabbot.cli import main

    out = tmp_path / "looks.png"
    assert main(["snapshot", "upper_right", "--out", str(out), "--width", "160", "--height",
                 "120", "--menagerie", str(fake.root)]) == 0
    assert out.is_file()
    assert main(["snapshot", "upper_right", "--out", str(out), "--menagerie",
                 str(tmp_path / "missing")]) == 2
    assert "menagerie_dir" in capsys.readouterr().err
