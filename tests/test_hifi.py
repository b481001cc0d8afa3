"""The MuJoCo car (rideid.hifi): an independent multibody model of the same physics."""

import numpy as np
import pytest

pytest.importorskip("mujoco")

from rideid.hifi import MujocoCar, simulate_mujoco  # noqa: E402
from rideid.model import CHANNEL_KIND, CHANNELS, static_corner_loads  # noqa: E402
from rideid.params import CORNERS, as_vector  # noqa: E402
from rideid.simulate import prepare_run, simulate_reference  # noqa: E402


def test_static_tire_deflection_is_load_over_stiffness(default_scenario):
    import mujoco
    P, geom = as_vector(default_scenario.truth), default_scenario.geometry
    car = MujocoCar(P, geom)
    m, d = car.model, car.data
    for _ in range(2000):  # 2 s held on level posts: the car must not move from its start
        car.set_road(np.zeros(4), np.zeros(4))
        mujoco.mj_step(m, d)
    loads = car.tire_loads()
    np.testing.assert_allclose(loads, static_corner_loads(P[None], geom)[0], rtol=1e-3)
    for i, c in enumerate(CORNERS):
        wheel = d.xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"wheel_{c}")][2]
        post = d.xpos[mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"post_{c}")][2]
        deflection = geom.tire_radius - (wheel - post)
        K = P[10] if c.startswith("f") else P[11]
        assert deflection == pytest.approx(loads[i] / K, rel=1e-3)
    assert abs(d.qpos[0]) < 1e-6  # heave: started in equilibrium (springref preload)


@pytest.mark.parametrize("rid", ["T_LL", "H_LL", "W_L"])
def test_mujoco_matches_the_seven_dof_model(rid, default_scenario):
    """CG at wheel-centre height, no wheel inertia: the same physics, within about 1 %."""
    sc = default_scenario
    P, geom, run = as_vector(sc.truth), sc.geometry, sc.run(rid)
    track = sc.tracks[run.track]
    t = np.arange(int(run.duration * 200) + 1) / 200
    y = simulate_mujoco(P, geom, track, run.speed, t)
    yr = simulate_reference(P[None], geom, prepare_run(track, geom, run.speed, t))[0]
    rms = np.sqrt(np.mean(yr ** 2, axis=0))
    err = np.sqrt(np.mean((y - yr) ** 2, axis=0))
    for i, c in enumerate(CHANNELS):
        same_kind = max(rms[j] for j, c2 in enumerate(CHANNELS) if CHANNEL_KIND[c2] == CHANNEL_KIND[c])
        if c == "roll_rate" or rms[i] > 1e-3 * same_kind:  # roll on a washboard: zero in both
            assert err[i] < 1e-2 * max(rms[i], 1e-3 * rms[8]), (c, err[i] / rms[i])


def test_simulate_engine_mujoco_from_the_command_line(tmp_path, default_scenario):
    """`rideid simulate --engine mujoco` writes a dataset that the 7-DOF model fits to within 1 %."""
    import tomli_w

    import rideid
    from rideid.cli import main
    doc = rideid.files.read_toml(rideid.default_scenario_path())
    doc["runs"] = [r for r in doc["runs"] if r["id"] in ("T_HL", "H_LL")]
    (tmp_path / "sc.toml").write_text(tomli_w.dumps(doc))
    assert main(["simulate", str(tmp_path / "sc.toml"), "--out", str(tmp_path / "ds"), "--engine", "mujoco",
                 "--quiet"]) == 0
    ds = rideid.load_dataset(tmp_path / "ds")
    cf = rideid.CostFunction(ds)
    truth = as_vector(default_scenario.truth)
    sims = cf.simulate(truth)
    for r in ds.runs:
        Y = ds.data[r.id].matrix()
        rel = np.sqrt(np.mean((sims[r.id] - Y) ** 2, axis=0)) / np.sqrt(np.mean(Y ** 2, axis=0))
        assert np.nanmax(rel[:9]) < 1e-2, (r.id, rel)
