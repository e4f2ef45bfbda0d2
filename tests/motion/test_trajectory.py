"""Trajectories: file formats, interpolation, velocity, generators, malformed input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from simspad.bundled import TRAJECTORIES_DIR
from simspad.cli import main
from simspad.errors import InputError
from simspad.io.trajectory_files import load_trajectory, save_trajectory
from simspad.motion.generators import Tremor, handheld_shake, linear_pan, object_rotation, orbit, static_pose
from simspad.motion.trajectory_summary import motion_summary
from simspad.motion.trajectory import Trajectory, TrajectorySet, look_at



def _random_trajectory(seed: int, n: int = 7, t0: float = 0.0) -> Trajectory:
    rng = np.random.default_rng(seed)
    times = t0 + np.cumsum(np.r_[0.0, rng.uniform(0.05, 0.3, n - 1)])
    positions = rng.normal(0.0, 1.0, (n, 3))
    # Smoothly varying orientations (successive rotations < 60°) so the spline is well conditioned.
    rotvecs = np.cumsum(rng.normal(0.0, 0.4, (n, 3)), axis=0)
    return Trajectory(times, positions, Rotation.from_rotvec(rotvecs).as_quat())


def _world_angular_velocity_fd(tr: Trajectory, t: np.ndarray, h: float) -> np.ndarray:
    r_minus, r_plus = tr.rotation(t - h), tr.rotation(t + h)
    return (r_plus * r_minus.inv()).as_rotvec() / (2 * h)


# ------------------------------------------------------------------------------------------------ round trips


@pytest.mark.parametrize("suffix", [".toml", ".json", ".csv", ".txt"])
def test_round_trip_every_format(tmp_path, suffix):
    camera = _random_trajectory(1)
    objects = {} if suffix == ".txt" else {"rotor blade, left": _random_trajectory(2, n=5), "door": _random_trajectory(3)}
    ts = TrajectorySet(camera, objects, "memory")
    path = save_trajectory(ts, tmp_path / f"traj{suffix}")
    back = load_trajectory(path)
    assert back.time_offset_s == 0.0
    assert set(back.objects) == set(objects)
    t = np.linspace(-0.1, camera.t_end + 0.1, 301)
    for name, tr in ts.bodies().items():
        tb = back.bodies()[name]
        np.testing.assert_allclose(tb.times_s, tr.times_s, rtol=0, atol=1e-12)
        np.testing.assert_allclose(tb.pose(t), tr.pose(t), rtol=0, atol=1e-9)
    assert not list(tmp_path.glob(".*tmp*")), "temporary file left behind"


def test_tum_refuses_objects(tmp_path):
    ts = TrajectorySet(_random_trajectory(1), {"door": _random_trajectory(2)})
    with pytest.raises(InputError, match="TUM"):
        save_trajectory(ts, tmp_path / "x.txt")
    assert not (tmp_path / "x.txt").exists()


# --------------------------------------------------------------------------------- interpolation and velocity


def test_pose_and_velocity_continuous_across_keyframes():
    tr = _random_trajectory(4, n=8)
    eps = 1e-7
    for tk in tr.times_s[1:-1]:
        left, right = tr.pose(tk - eps), tr.pose(tk + eps)
        assert np.abs(left - right).max() < 1e-5
        np.testing.assert_allclose(tr.pose(tk)[:3, 3], tr.positions_m[tr.times_s == tk][0], atol=1e-12)
        v_l, w_l = tr.velocity(tk - eps)
        v_r, w_r = tr.velocity(tk + eps)
        assert np.abs(v_l - v_r).max() < 1e-4 * (1 + np.abs(v_l).max())
        assert np.abs(w_l - w_r).max() < 1e-4 * (1 + np.abs(w_l).max())
    # keyframes are interpolated exactly
    np.testing.assert_allclose(tr.pose(tr.times_s)[:, :3, 3], tr.positions_m, atol=1e-12)
    q = Rotation.from_matrix(tr.pose(tr.times_s)[:, :3, :3]).as_quat()
    dots = np.abs(np.sum(q * tr.quaternions_xyzw, axis=1))
    np.testing.assert_allclose(dots, 1.0, atol=1e-12)


def test_velocity_matches_finite_differences():
    tr = _random_trajectory(5, n=9)
    t = np.linspace(tr.t_start + 0.01, tr.t_end - 0.01, 200)
    h = 1e-6
    v, w = tr.velocity(t)
    v_fd = (tr.position(t + h) - tr.position(t - h)) / (2 * h)
    w_fd = _world_angular_velocity_fd(tr, t, h)
    np.testing.assert_allclose(v, v_fd, rtol=0, atol=1e-5 * (1 + np.abs(v).max()))
    np.testing.assert_allclose(w, w_fd, rtol=0, atol=1e-5 * (1 + np.abs(w).max()))
    assert np.abs(w).max() > 0.5, "test trajectory should rotate"


def test_outside_span_holds_end_poses_with_zero_velocity():
    tr = _random_trajectory(6)
    np.testing.assert_allclose(tr.pose(tr.t_end + 5.0), tr.pose(tr.t_end), atol=1e-12)
    v, w = tr.velocity(np.array([tr.t_start - 1.0, tr.t_end + 1.0]))
    assert not v.any() and not w.any()


def test_look_at_matches_mitsuba():
    mi = pytest.importorskip("mitsuba")
    for origin, target, up in [([1, 2, 3], [0, 0, 0], [0, 1, 0]), ([0, 0, 2], [0.3, -0.2, 0], [0, 1, 0.2])]:
        ref = np.array(mi.scalar_rgb.ScalarTransform4f.look_at(origin=origin, target=target, up=up).matrix)
        np.testing.assert_allclose(look_at(origin, target, up), ref, atol=1e-6)


# ----------------------------------------------------------------------------------------------- TUM import


def _write_realistic_tum(path: Path, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t0 = 1305031102.175304
    stamps = t0 + np.cumsum(np.r_[0.0, rng.normal(1 / 30, 0.003, 59).clip(0.02, 0.05)])
    s = stamps - t0
    pos = np.stack([1.34 + 0.2 * s, 0.62 + 0.01 * np.sin(2 * np.pi * 1.7 * s), 1.65 + 0.003 * s], axis=1)
    rot = Rotation.from_quat([0.6574, 0.6126, -0.2949, -0.3248]) * Rotation.from_rotvec(np.outer(0.2 * s, [0.0, 1.0, 0.0]))
    q = rot.as_quat()
    lines = ["# ground truth trajectory", "# file: 'rgbd_dataset_freiburg1_xyz.bag'", "# timestamp tx ty tz qx qy qz qw"]
    lines += [f"{t:.6f} {p[0]:.4f} {p[1]:.4f} {p[2]:.4f} {qq[0]:.4f} {qq[1]:.4f} {qq[2]:.4f} {qq[3]:.4f}"
              for t, p, qq in zip(stamps, pos, q)]
    path.write_text("\n".join(lines) + "\n")
    return stamps, pos


def test_tum_import_of_realistic_file(tmp_path):
    stamps, pos = _write_realistic_tum(tmp_path / "groundtruth.txt")
    ts = load_trajectory(tmp_path / "groundtruth.txt")
    assert ts.objects == {}
    assert ts.time_offset_s == pytest.approx(1305031102.175304, abs=1e-6)
    tr = ts.camera
    assert len(tr.times_s) == 60 and tr.t_start == 0.0
    np.testing.assert_allclose(tr.times_s, stamps - stamps[0], atol=1e-6)  # µs stamps survive rebasing
    np.testing.assert_allclose(tr.positions_m, np.round(pos, 4), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(tr.quaternions_xyzw, axis=1), 1.0, atol=1e-12)
    v, w = tr.velocity(np.linspace(0.1, tr.t_end - 0.1, 50))
    assert np.median(v[:, 0]) == pytest.approx(0.2, abs=0.02)  # the recorded drift speed
    assert np.median(np.linalg.norm(w, axis=1)) == pytest.approx(0.2, abs=0.02)
    kept = load_trajectory(tmp_path / "groundtruth.txt", rebase=False)
    assert kept.time_offset_s == 0.0 and kept.camera.t_start == pytest.approx(stamps[0], abs=1e-6)


def test_bundled_example_trajectories_load():
    for path in sorted(TRAJECTORIES_DIR.glob("example_*")):
        ts = load_trajectory(path)
        assert ts.camera is not None and ts.t_end > ts.t_start, path


# ---------------------------------------------------------------------------------------------- bad input


def _assert_refused(path: Path, *fragments: str) -> str:
    with pytest.raises(InputError) as info:
        load_trajectory(path)
    msg = str(info.value)
    assert str(path) in msg
    for f in fragments:
        assert f in msg, msg
    return msg


def test_refuses_non_increasing_times(tmp_path):
    p = tmp_path / "t.txt"
    p.write_text("# c\n1.0 0 0 0 0 0 0 1\n1.5 0 0 0 0 0 0 1\n1.5 0 0 1 0 0 0 1\n")
    _assert_refused(p, "line 4", "strictly increasing")


def test_refuses_nan(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("t,tx,ty,tz,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n1,nan,0,0,0,0,0,1\n")
    _assert_refused(p, "line 3", "NaN")


def test_refuses_non_unit_quaternion_and_says_the_norm(tmp_path):
    p = tmp_path / "t.toml"
    p.write_text("[camera]\nkeyframes = [\n {t = 0, position = [0,0,0], quaternion_xyzw = [0,0,0,1]},\n"
                 " {t = 1, position = [0,0,0], quaternion_xyzw = [0,0,0.5,1]},\n]\n")
    _assert_refused(p, "camera.keyframes[1].quaternion_xyzw", "norm 1.11803")


def test_refuses_missing_columns(tmp_path):
    p = tmp_path / "t.csv"
    p.write_text("t,tx,ty,tz,qx,qy,qw\n0,0,0,0,0,0,1\n")
    _assert_refused(p, "line 1", "missing column(s) qz")


def test_refuses_short_tum_line(tmp_path):
    p = tmp_path / "t.tum"
    p.write_text("0 0 0 0 0 0 0 1\n1 0 0 0 0 0 1\n")
    _assert_refused(p, "line 2", "expected 8")


def test_refuses_single_keyframe(tmp_path):
    p = tmp_path / "t.json"
    p.write_text('{"camera": {"keyframes": [{"t": 0, "position": [0, 0, 0]}]}}')
    _assert_refused(p, "camera.keyframes", "at least 2", "static_pose")


def test_refuses_unknown_generator(tmp_path):
    p = tmp_path / "t.toml"
    p.write_text('[objects.fan]\ngenerator = "wobble"\n')
    _assert_refused(p, "objects.fan.generator", "unknown generator 'wobble'", "object_rotation")


def test_refuses_missing_file_and_unknown_format(tmp_path):
    _assert_refused(tmp_path / "none.toml", "not found")
    p = tmp_path / "t.yaml"
    p.write_text("x")
    _assert_refused(p, "unknown trajectory format")


def test_cli_reports_malformed_trajectory_in_one_line(tmp_path, capsys):
    p = tmp_path / "t.txt"
    p.write_text("0 0 0 0 0 0 0 1\n0 0 0 0 0 0 0 1\n")
    assert main(["info", str(p)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and "line 2" in err


# ----------------------------------------------------------------------------------------------- generators


def test_handheld_shake_amplitude_band_and_seed():
    f_lo, f_hi, amp_m, amp_deg, dur = 3.0, 11.0, 0.002, 0.4, 20.0
    tremor = Tremor(f_lo_hz=f_lo, f_hi_hz=f_hi, translation_amplitude_m=amp_m, rotation_amplitude_deg=amp_deg)
    tr = handheld_shake(seed=11, tremor=tremor, duration_s=dur)
    rate = 500.0
    t = np.arange(0, dur, 1 / rate)
    x = tr.position(t)
    rv = tr.rotation(t).as_rotvec()
    # per-axis RMS equals the configured amplitude (finite-time cross terms are small for 20 s)
    np.testing.assert_allclose(x.std(axis=0), amp_m, rtol=0.15)
    np.testing.assert_allclose(np.rad2deg(rv.std(axis=0)), amp_deg, rtol=0.15)
    # spectrum: (Hann-windowed) energy inside the band, allowing 3 bins of leakage
    freqs = np.fft.rfftfreq(len(t), 1 / rate)
    window = np.hanning(len(t))[:, None]
    for signal in (x, rv):
        power = np.abs(np.fft.rfft((signal - signal.mean(axis=0)) * window, axis=0)) ** 2
        df = freqs[1]
        inside = (freqs >= f_lo - 3 * df) & (freqs <= f_hi + 3 * df)
        assert power[inside].sum() / power.sum() > 0.999
    same = handheld_shake(seed=11, tremor=tremor, duration_s=dur)
    other = handheld_shake(seed=12, tremor=tremor, duration_s=dur)
    assert np.array_equal(same.positions_m, tr.positions_m)
    assert not np.allclose(other.positions_m, tr.positions_m)


def test_handheld_pan_turns_at_its_rate_with_the_tremor_riding_on_it():
    tremor = Tremor(f_lo_hz=3.0, f_hi_hz=11.0, translation_amplitude_m=0.002, rotation_amplitude_deg=0.4)
    base_q = Rotation.from_rotvec([0.1, -0.3, 0.05]).as_quat()
    still = handheld_shake(seed=5, tremor=tremor, quaternion_xyzw=base_q, duration_s=1.0)
    pan = handheld_shake(seed=5, tremor=tremor, quaternion_xyzw=base_q, duration_s=1.0,
                         yaw_rate_deg_s=-60.0, start_yaw_deg=6.0)
    t = np.linspace(0.0, 1.0, 41)
    # Removing the analytic turn about world up from the pan leaves exactly the still camera's tremor.
    turn = Rotation.from_rotvec(np.deg2rad(6.0 - 60.0 * t)[:, None] * [0.0, 1.0, 0.0])
    residual = (turn.inv() * pan.rotation(t)) * still.rotation(t).inv()
    assert np.rad2deg(residual.magnitude()).max() < 1e-3
    np.testing.assert_allclose(pan.position(t), still.position(t), atol=1e-12)  # turns about its own origin
    # Mean angular rate over the second is the pan's (tremor averages out to a few tenths of a degree per second).
    _, w = pan.velocity(np.linspace(0.0, 1.0, 2001))
    assert np.rad2deg(w[:, 1].mean()) == pytest.approx(-60.0, abs=1.0)
    # A zero pan gives the plain shake bit for bit (the bundled default trajectories keep their renders).
    zero = handheld_shake(seed=5, tremor=tremor, quaternion_xyzw=base_q, duration_s=1.0, yaw_rate_deg_s=0.0,
                          axis=(0.0, 0.0, 1.0))
    assert np.array_equal(zero.quaternions_xyzw, still.quaternions_xyzw)


def test_object_rotation_rpm_gives_right_angle():
    center, axis = np.array([0.5, 0.8, -1.0]), np.array([0.0, 0.0, 1.0])
    tr = object_rotation(center, axis, rpm=15.0, duration_s=2.0)  # 15 rpm = 90° per second
    np.testing.assert_allclose(tr.rotation(1.0).as_rotvec(), [0, 0, np.pi / 2], atol=1e-9)
    m = tr.pose(1.0)
    np.testing.assert_allclose(m[:3, :3] @ center + m[:3, 3], center, atol=1e-12)  # centre is fixed
    rim = center + np.array([0.2, 0.0, 0.0])
    np.testing.assert_allclose(m[:3, :3] @ rim + m[:3, 3], center + [0.0, 0.2, 0.0], atol=1e-7)
    _, w = tr.velocity(0.7)
    np.testing.assert_allclose(w, [0, 0, 2 * np.pi * 15 / 60], atol=1e-6)
    fast = object_rotation(center, axis, rpm=3000.0, duration_s=0.02)  # a fan: 50 rev/s
    np.testing.assert_allclose(fast.rotation(0.0125).as_rotvec()[2] % (2 * np.pi),
                               (2 * np.pi * 50 * 0.0125) % (2 * np.pi), atol=1e-6)


def test_orbit_and_linear_pan():
    target = np.array([0.1, 0.5, -0.2])
    tr = orbit(target, radius_m=2.0, angular_speed_deg_s=90.0, height_m=0.5, duration_s=4.0)
    t = np.linspace(0, 4, 97)
    m = tr.pose(t)
    horiz = m[:, :3, 3] - target - [0, 0.5, 0]
    np.testing.assert_allclose(np.linalg.norm(horiz, axis=1), 2.0, rtol=1e-6)
    to_target = target - m[:, :3, 3]
    to_target /= np.linalg.norm(to_target, axis=1, keepdims=True)
    np.testing.assert_allclose(m[:, :3, 2], to_target, atol=1e-6)  # camera +Z looks at the target
    v, _ = tr.velocity(t[1:-1])
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 2.0 * np.pi / 2, rtol=1e-4)
    pan = linear_pan(velocity_m_s=[0.1, 0, 0.3], yaw_rate_deg_s=20.0, duration_s=1.0)
    v, w = pan.velocity(np.array([0.2, 0.5]))
    np.testing.assert_allclose(v, [[0.1, 0, 0.3]] * 2, atol=1e-9)
    np.testing.assert_allclose(w, [[0, np.deg2rad(20.0), 0]] * 2, atol=1e-9)
    still = static_pose([1, 2, 3], duration_s=0.5)
    assert motion_summary(still)["max_speed_m_s"] == 0.0 and still.t_end == 0.5


def test_generator_table_in_toml(tmp_path, capsys):
    p = tmp_path / "gen.toml"
    p.write_text('[camera]\ngenerator = "linear_pan"\nposition = [0, 1, 2]\nvelocity_m_s = [0.5, 0, 0]\n'
                 'yaw_rate_deg_s = 30\nduration_s = 2\n\n[objects.fan]\ngenerator = "object_rotation"\nrpm = 600\n')
    ts = load_trajectory(p)
    assert ts.t_start == 0.0 and ts.t_end == 1.0  # the object (default 1 s) limits the common span
    s = motion_summary(ts.camera)
    assert s["path_length_m"] == pytest.approx(1.0, rel=1e-9)
    assert s["max_speed_m_s"] == pytest.approx(0.5, rel=1e-9)
    assert np.rad2deg(s["max_angular_rate_rad_s"]) == pytest.approx(30.0, rel=1e-9)
    assert main(["info", str(p)]) == 0
    out = capsys.readouterr().out
    for word in ("duration", "path length", "max speed", "max angular rate", "camera", "fan"):
        assert word in out
    bad = tmp_path / "bad.toml"
    bad.write_text('[camera]\ngenerator = "orbit"\nradius_m = -1\n')
    _assert_refused(bad, "camera.radius_m", "> 0")
