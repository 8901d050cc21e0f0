"""`chaingen export SCENE --mjcf OUT.xml`: MuJoCo loads the file, and with the same torques its
angles agree with ours (issue 18 d: actuation, damping and a multi-articular spring)."""
from __future__ import annotations

import numpy as np
import pytest

from chaingen import build_solver, load_reference_scene

from helpers import ROOT, chaingen_in_process, scene_path

mujoco = pytest.importorskip("mujoco")

SCENE = ROOT / "scenes" / "four_link_actuated.toml"   # 4 links, all actuated, damped, a
                                                       # mono- and a bi-articular spring


def export(tmp_path, *arguments):
    out = tmp_path / "chain.xml"
    result = chaingen_in_process("export", SCENE, "--mjcf", out, *arguments, cwd=tmp_path)
    return result, out


def test_export_writes_a_model_mujoco_loads(tmp_path):
    result, out = export(tmp_path, "--dt", "0.001")
    assert result.returncode == 0, result.stderr
    model = mujoco.MjModel.from_xml_path(str(out))
    scene = load_reference_scene("four_link_actuated")
    assert (model.nq, model.nu, model.ntendon) == (4, 4, 2)
    assert model.opt.timestep == 0.001 and model.ngeom == 4
    np.testing.assert_allclose(model.body_mass[1:], [link.mass for link in scene.links])
    np.testing.assert_allclose(model.dof_damping, [link.damping for link in scene.links])
    assert all(model.geom_contype == 0) and all(model.geom_conaffinity == 0)


@pytest.mark.parametrize("arguments, message", [
    (("--dt", "0"), "--dt: must be > 0"),
    (("--integrator", "rk4"), "--integrator: must be one of"),
])
def test_bad_options_exit_2_and_write_nothing(tmp_path, arguments, message):
    result, out = export(tmp_path, *arguments)
    assert result.returncode == 2 and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and not out.exists()


def test_a_scene_mujoco_cannot_represent_is_refused(tmp_path):
    scene = tmp_path / "point_masses.toml"
    scene.write_text(scene_path("three_link_mono").read_text().replace("inertia = 1.0",
                                                                          "inertia = 0.0"))
    out = tmp_path / "out.xml"
    result = chaingen_in_process("export", scene, "--mjcf", out, cwd=tmp_path)
    assert result.returncode == 2, result.stdout + result.stderr
    assert "inertia" in result.stderr and not out.exists()


@pytest.mark.compile
@pytest.mark.parametrize("method", ["es", "midpoint"])
def test_angles_agree_with_mujoco_on_the_exported_model(tmp_path, method):
    """Both driven by the same smooth torques, held over each step (ours: row k over step k;
    MuJoCo: data.ctrl set before mj_step), RK4 at dt = 1e-4: the angles at t = 1 s within
    1e-5 rad."""
    dt, n_steps = 1e-4, 10_000
    result, out = export(tmp_path, "--dt", repr(dt))
    assert result.returncode == 0, result.stderr
    scene = load_reference_scene("four_link_actuated")
    solver = build_solver(scene, method, 3, sensitivities=False)
    hold = solver.holding_torques(np.array(scene.initial_angles))
    t = np.arange(n_steps) * dt
    torques = hold + np.outer(np.sin(2.0 * t), [2.0, -1.0, 0.5, 0.2])
    ours = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                           n_steps=n_steps, torques=torques)
    model = mujoco.MjModel.from_xml_path(str(out))
    data = mujoco.MjData(model)
    data.qpos[:] = scene.initial_angles
    data.qvel[:] = scene.initial_velocities
    mujoco.mj_forward(model, data)
    for k in range(n_steps):
        data.ctrl[:] = torques[k]
        mujoco.mj_step(model, data)
    difference = np.angle(np.exp(1j * (ours.phi[-1] - data.qpos)))   # wrapped
    print(f"{method}: max |phi - phi_MuJoCo| at t = 1 s: {np.abs(difference).max():.2e} rad")
    assert np.abs(difference).max() <= 1e-5


@pytest.mark.parametrize("scene_name, old, new, count, geoms", [
    # Every link 1e-7 m: MuJoCo refused the file ('fromto points too close in geom').
    ("three_link_mono", "length = 1.0", "length = 1e-7", 3, 0),
    ("three_link_mono", "length = 1.0", "length = 1e-300", 1, 2),      # the first link only
    # Joint 3 1e-8 m from joint 2: link 2's capsule (spatial: origin to the next joint).
    ("spatial_three_link", "xyz = [0.3, 0.0, 0.0]", "xyz = [1e-8, 0.0, 0.0]", 1, 2),
])
def test_export_of_links_too_short_for_a_capsule_loads(tmp_path, scene_name, old, new, count,
                                                       geoms):
    """The capsules only draw the links (no mass, no contacts): one MuJoCo's compiler refuses,
    1e-7 m long or shorter, is left out, and the file loads (it did not, exit 0 before)."""
    text = scene_path(scene_name).read_text()
    assert text.count(old) >= count
    scene = tmp_path / "arm.toml"
    scene.write_text(text.replace(old, new, count))
    out = tmp_path / "arm.xml"
    result = chaingen_in_process("export", scene, "--mjcf", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    model = mujoco.MjModel.from_xml_path(str(out))
    assert (model.nq, model.ngeom) == (3, geoms)
