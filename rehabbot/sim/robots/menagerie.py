"""Optional looks: draw our UR5e with the meshes of a local MuJoCo Menagerie checkout.

Nothing here is needed to simulate, and nothing is downloaded: the user points the scene
option ``menagerie_dir`` (or ``rehabbot view --menagerie DIR``) at their own clone of
``mujoco_menagerie``, and the visual meshes of its ``universal_robots_ur5e/ur5e.xml`` are
referenced from that folder by absolute path.

The menagerie model's body frames are not our DH frames, and its base is rotated relative to the
UR base frame. Rather than hard-coding those offsets, :func:`add_menagerie_visuals` measures
them: it puts both robots at the same random joint angles, fits the rigid transform between the
two worlds from the flange positions (Kabsch), checks that the fit is good (same kinematics) and
that each body's relative transform is constant, and then re-parents every visual mesh geom onto
the matching body of our robot. Collision stays on our own capsules, which move to geom group 3
(not drawn by default).

This module is imported only when the option is used: ``import rehabbot.sim`` does not load it.
"""

from __future__ import annotations

import os
from pathlib import Path

import mujoco
import numpy as np

from rehabbot.sim.robots import ur5e as ur

MENAGERIE_FOLDER = "universal_robots_ur5e"
MENAGERIE_XML = "ur5e.xml"

# Our body (without prefix) -> the menagerie body that carries the same link.
BODY_MAP: tuple[tuple[str, str], ...] = (
    ("base", "base"),
    ("link1", "shoulder_link"),
    ("link2", "upper_arm_link"),
    ("link3", "forearm_link"),
    ("link4", "wrist_1_link"),
    ("link5", "wrist_2_link"),
    ("link6", "wrist_3_link"),
)
# The menagerie names its joints "<our joint name>_joint" and the flange site "attachment_site".
MENAGERIE_JOINTS: tuple[str, ...] = tuple(f"{name}_joint" for name in ur.JOINT_NAMES)
MENAGERIE_FLANGE_SITE = "attachment_site"

# The flange positions of both models must agree to this after alignment [m]. The menagerie's
# link lengths are rounded to the millimetre (e.g. d1 = 0.163 m vs UR's 0.1625 m), which leaves
# about a millimetre; a different robot or a scaled link leaves centimetres.
KINEMATIC_TOLERANCE_M = 2e-3
# How constant each body's relative transform must be across joint angles. With exact
# kinematics it is constant to ~1e-12; the menagerie's rounding moves it by about a millimetre /
# a milliradian; a joint turning the wrong way moves it by whole radians.
FRAME_DRIFT_TOLERANCE_M = 5e-3
FRAME_DRIFT_TOLERANCE_RAD = 0.02
N_SAMPLES = 10
# Our geoms that are not part of the arm (the rehab cuff and its bracket) stay drawn.
KEEP_VISIBLE = ("cuff", "cuff_bracket")
VISUAL_GROUP = 2
HIDDEN_GROUP = 3


def find_menagerie_ur5e(root: str | os.PathLike) -> Path:
    """The path of the menagerie's ``ur5e.xml``, given the menagerie root, its
    ``universal_robots_ur5e`` folder, or the xml file itself (``~`` is expanded).

    Raises ``FileNotFoundError`` naming the places looked at.
    """
    base = Path(os.fspath(root)).expanduser()
    if base.is_file():
        return base.resolve()
    candidates = (base / MENAGERIE_XML, base / MENAGERIE_FOLDER / MENAGERIE_XML)
    for candidate in candidates:
        if candidate.is_file():
            return candidate.resolve()
    looked = ", ".join(str(c) for c in candidates)
    raise FileNotFoundError(
        f"no MuJoCo Menagerie UR5e found at {str(base)!r}: looked for {looked} (give the "
        f"mujoco_menagerie folder, its {MENAGERIE_FOLDER} folder or {MENAGERIE_XML} itself)")


# ---------------------------------------------------------------------------------- transforms
def _pose(pos, quat) -> np.ndarray:
    quat = np.asarray(quat, dtype=float)
    norm = np.linalg.norm(quat)
    if not norm > 0:
        raise ValueError(f"zero quaternion {quat}")
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat / norm)
    out = np.eye(4)
    out[:3, :3] = mat.reshape(3, 3)
    out[:3, 3] = pos
    return out


def _pose_from_data(xpos, xmat) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = np.asarray(xmat).reshape(3, 3)
    out[:3, 3] = xpos
    return out


def _inverse(pose: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = pose[:3, :3].T
    out[:3, 3] = -pose[:3, :3].T @ pose[:3, 3]
    return out


def _quat(pose: np.ndarray) -> np.ndarray:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(pose[:3, :3]).ravel())
    return quat


def _rotation_angle(rot: np.ndarray) -> float:
    return float(np.arccos(np.clip((np.trace(rot) - 1.0) / 2.0, -1.0, 1.0)))


def kabsch(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The proper rigid transform (4x4) that best maps points ``source`` (n, 3) onto ``target``."""
    src_mean, dst_mean = source.mean(axis=0), target.mean(axis=0)
    cov = (source - src_mean).T @ (target - dst_mean)
    u, _, vt = np.linalg.svd(cov)
    fix = np.diag([1.0, 1.0, np.sign(np.linalg.det(vt.T @ u.T))])
    rot = vt.T @ fix @ u.T
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = dst_mean - rot @ src_mean
    return out


def _local_pose(spec: mujoco.MjSpec, element) -> np.ndarray:
    """Pose of a spec element (geom or frame) in its parent, resolving alternative orientations."""
    if element.alt.type == mujoco.mjtOrientation.mjORIENTATION_QUAT:
        quat = element.quat
    else:
        quat = spec.resolve_orientation(spec.compiler.degree, spec.compiler.eulerseq,
                                        element.alt)
    return _pose(element.pos, quat)


def _geom_in_body(spec: mujoco.MjSpec, geom) -> np.ndarray:
    """Pose of a spec geom in its body frame, through any enclosing ``<frame>`` elements."""
    pose = _local_pose(spec, geom)
    frame = geom.frame
    while frame is not None:
        pose = _local_pose(spec, frame) @ pose
        frame = frame.frame
    return pose


# ---------------------------------------------------------------------------------- alignment
def _menagerie_ids(model: mujoco.MjModel, xml_path: Path):
    """Body ids, joint qpos addresses and flange site id of the compiled menagerie model."""
    missing = []

    def lookup(kind, name):
        try:
            return getattr(model, kind)(name).id
        except KeyError:
            missing.append(f"{kind} {name!r}")
            return -1

    body_ids = [lookup("body", name) for _, name in BODY_MAP]
    joint_ids = [lookup("joint", name) for name in MENAGERIE_JOINTS]
    site_id = lookup("site", MENAGERIE_FLANGE_SITE)
    if missing:
        raise ValueError(f"{xml_path} is not the Menagerie UR5e: it has no {', '.join(missing)}")
    for name, jid in zip(MENAGERIE_JOINTS, joint_ids, strict=True):
        if model.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE:
            raise ValueError(f"{xml_path}: joint {name!r} is not a hinge")
    return body_ids, model.jnt_qposadr[joint_ids], site_id


def menagerie_link_transforms(menagerie: mujoco.MjModel,
                              xml_path: Path | str = "ur5e.xml") -> dict[str, np.ndarray]:
    """For each of our bodies (no prefix), the constant 4x4 pose of the matching menagerie body
    frame in our body frame.

    Raises ``ValueError`` if the menagerie model does not have the UR5e's kinematics.
    """
    xml_path = Path(xml_path)
    men_bodies, men_qadr, men_site = _menagerie_ids(menagerie, xml_path)
    ours = ur.build_ur5e_spec().compile()
    our_bodies = [ours.body(name).id for name, _ in BODY_MAP]
    our_qadr = np.array([ours.joint(name).qposadr[0] for name in ur.JOINT_NAMES])
    our_site = ours.site("tool").id
    our_data, men_data = mujoco.MjData(ours), mujoco.MjData(menagerie)

    def poses(q: np.ndarray):
        our_data.qpos[our_qadr] = q
        men_data.qpos[:] = menagerie.qpos0
        men_data.qpos[men_qadr] = q
        mujoco.mj_kinematics(ours, our_data)
        mujoco.mj_kinematics(menagerie, men_data)
        our_links = [_pose_from_data(our_data.xpos[b], our_data.xmat[b]) for b in our_bodies]
        men_links = [_pose_from_data(men_data.xpos[b], men_data.xmat[b]) for b in men_bodies]
        return (our_links, men_links, our_data.site_xpos[our_site].copy(),
                men_data.site_xpos[men_site].copy())

    rng = np.random.default_rng(20240601)
    samples = rng.uniform(-np.pi, np.pi, size=(N_SAMPLES, len(ur.JOINT_NAMES)))
    our_tool, men_tool = [], []
    for q in samples:
        _, _, our_p, men_p = poses(q)
        our_tool.append(our_p)
        men_tool.append(men_p)
    our_tool, men_tool = np.array(our_tool), np.array(men_tool)
    world = kabsch(men_tool, our_tool)  # menagerie world -> our world (= our base frame)
    fitted = men_tool @ world[:3, :3].T + world[:3, 3]
    residual = float(np.max(np.linalg.norm(fitted - our_tool, axis=1)))
    if residual > KINEMATIC_TOLERANCE_M:
        raise ValueError(
            f"{xml_path} does not match the UR5e kinematics: after the best rigid alignment its "
            f"flange ({MENAGERIE_FLANGE_SITE!r}) is {residual * 1000:.1f} mm from ours "
            f"(tolerance {KINEMATIC_TOLERANCE_M * 1000:.0f} mm)")

    def relative(q: np.ndarray) -> list[np.ndarray]:
        our_links, men_links, _, _ = poses(q)
        return [_inverse(o) @ world @ m for o, m in zip(our_links, men_links, strict=True)]

    at_zero = relative(np.zeros(len(ur.JOINT_NAMES)))
    for q in samples:
        for (name, men_name), ref, other in zip(BODY_MAP, at_zero, relative(q), strict=True):
            drift_m = float(np.linalg.norm(other[:3, 3] - ref[:3, 3]))
            drift_rad = _rotation_angle(ref[:3, :3].T @ other[:3, :3])
            if drift_m > FRAME_DRIFT_TOLERANCE_M or drift_rad > FRAME_DRIFT_TOLERANCE_RAD:
                raise ValueError(
                    f"{xml_path} does not match the UR5e kinematics: body {men_name!r} does not "
                    f"move rigidly with our {name!r} (drift {drift_m * 1000:.1f} mm, "
                    f"{np.degrees(drift_rad):.2f} deg at q = {np.round(q, 3).tolist()} rad); "
                    "a joint turns the other way or has another zero")
    return {name: pose for (name, _), pose in zip(BODY_MAP, at_zero, strict=True)}


# ---------------------------------------------------------------------------------- copying
def _is_visual_mesh(geom) -> bool:
    return (geom.type == mujoco.mjtGeom.mjGEOM_MESH and geom.contype == 0
            and geom.conaffinity == 0)


def _mesh_file(menagerie: mujoco.MjSpec, xml_path: Path, mesh) -> Path:
    file = Path(mesh.file)
    if file.is_absolute():
        return file
    meshdir = Path(menagerie.compiler.meshdir or menagerie.meshdir or "")
    if not meshdir.is_absolute():
        meshdir = xml_path.parent / meshdir
    return meshdir / file


def _copy_mesh(spec: mujoco.MjSpec, name: str, menagerie: mujoco.MjSpec, xml_path: Path,
               mesh) -> None:
    if spec.mesh(name) is not None:
        return
    new = spec.add_mesh(name=name)
    if mesh.file:
        path = _mesh_file(menagerie, xml_path, mesh)
        if not path.is_file():
            raise FileNotFoundError(f"menagerie mesh {str(path)!r} (from {xml_path}) not found")
        new.file = str(path)
        if mesh.content_type:
            new.content_type = mesh.content_type
    else:  # vertices written in the xml
        for field in ("uservert", "userface", "usernormal", "userfacenormal"):
            setattr(new, field, list(getattr(mesh, field)))
    new.scale = list(mesh.scale)
    new.refpos = list(mesh.refpos)
    new.refquat = list(mesh.refquat)
    new.inertia = mesh.inertia
    new.maxhullvert = mesh.maxhullvert
    new.smoothnormal = mesh.smoothnormal


def _rgba(menagerie: mujoco.MjSpec, geom) -> list[float]:
    material = menagerie.material(geom.material) if geom.material else None
    return list(material.rgba) if material is not None else list(geom.rgba)


def add_menagerie_visuals(spec: mujoco.MjSpec, prefix: str, xml_path: str | os.PathLike) -> int:
    """Draw the robot ``prefix`` in ``spec`` with the menagerie UR5e's visual meshes.

    ``xml_path`` is the menagerie's ``ur5e.xml`` (or a folder :func:`find_menagerie_ur5e`
    accepts). Every visual mesh geom (type mesh, contype 0, conaffinity 0) of each menagerie link
    is added, at its measured pose, to our matching body as geom
    ``{prefix}menagerie_<menagerie body>_<k>`` (contype 0, conaffinity 0, group 2, rgba = its
    material's colour); the mesh files are referenced where they lie. Our own geoms of the arm
    move to group 3: they keep colliding but are not drawn by default (the cuff and its bracket
    stay drawn). Returns the number of mesh geoms added.

    Raises ``FileNotFoundError`` if the model or a mesh file is missing, and ``ValueError`` if the
    model does not have the UR5e's kinematics.
    """
    xml_path = find_menagerie_ur5e(xml_path)
    menagerie = mujoco.MjSpec.from_file(str(xml_path))
    try:
        compiled = menagerie.compile()
    except ValueError as err:
        raise ValueError(f"cannot compile {xml_path}: {err}") from err
    transforms = menagerie_link_transforms(compiled, xml_path)

    added = 0
    for ours, men_name in BODY_MAP:
        body = spec.body(f"{prefix}{ours}")
        if body is None:
            raise ValueError(f"spec has no body {prefix}{ours!r}: add the UR5e first")
        own = list(body.geoms)
        link = transforms[ours]
        visuals = [g for g in menagerie.body(men_name).geoms if _is_visual_mesh(g)]
        for k, geom in enumerate(visuals):
            mesh = menagerie.mesh(geom.meshname)
            if mesh is None:
                raise ValueError(f"{xml_path}: geom on {men_name!r} uses unknown mesh "
                                 f"{geom.meshname!r}")
            mesh_name = f"{prefix}menagerie_{geom.meshname}"
            _copy_mesh(spec, mesh_name, menagerie, xml_path, mesh)
            pose = link @ _geom_in_body(menagerie, geom)
            new = body.add_geom(name=f"{prefix}menagerie_{men_name}_{k}",
                                type=mujoco.mjtGeom.mjGEOM_MESH, meshname=mesh_name,
                                pos=list(pose[:3, 3]), quat=list(_quat(pose)),
                                rgba=_rgba(menagerie, geom))
            new.contype, new.conaffinity, new.group = 0, 0, VISUAL_GROUP
            added += 1
        keep = {f"{prefix}{name}" for name in KEEP_VISIBLE}
        for geom in own:
            if geom.name.startswith(prefix) and geom.name not in keep:
                geom.group = HIDDEN_GROUP
    return added
