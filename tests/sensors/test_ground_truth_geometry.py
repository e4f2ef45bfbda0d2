"""Ground-truth geometry of recordings (issue 37): instance masks, intrinsics, poses and the motion field, checked
against truths that do not go through SimSPAD's own reprojection code.

- The Siemens star spins about the optical axis: its image motion is a rotation about the principal point, ω × r,
  with ω from the trajectory file (60 rpm about +Z, right-handed).
- A camera that only rotates sees every pixel move by the homography K·R·K⁻¹, whatever the depth.
- On the office (a fast hand-held pan) and the fan (spinning blades), the ground-truth image at t + Δt sampled at
  x + flow(x) reproduces the image at t wherever the flow is valid, within the render's own Monte Carlo noise on
  the office and within 1.6 times it on the fan (whose pitched blades change brightness as they turn), where
  resampling is exact to first order; and the flow is the motion (half a pixel off is worse; on the office, no
  flow is far worse).
- The flow equals the finite difference of the recording's own depth, K and poses (an independent pinhole in
  OpenCV's convention), and the instantaneous velocity the derivative of the trajectory's poses.

Renders are tiny (64 × 48 px, a few milliseconds); each scene is rendered once per module. The geometry checks
themselves (star, rotation, finite differences) hold to 10⁻³ px, far inside the issue's 0.05 px.
"""

from __future__ import annotations

import json
import math
import tomllib

import h5py
import numpy as np
import pytest
from scipy.ndimage import map_coordinates, sobel
from scipy.spatial.transform import Rotation

from simspad.bundled import find_trajectory
from simspad.dataset.speed import retimed
from simspad.io.trajectory_files import load_trajectory
from simspad.render.renderer import RenderSettings, render_sequence
from simspad.sensors.simulate import RecordingSettings, simulate_recording

W, H = 64, 48
CV = np.diag([-1.0, -1.0, 1.0])  # Mitsuba camera axes (x left, y up) -> OpenCV's (x right, y down)


def _record(tmp, scene, trajectory, *, duration_s, spp=4, seed=0, gt_rate_hz=1000.0, name=None):
    out = tmp / (name or scene)
    render_sequence(scene, trajectory, RenderSettings(duration_s=duration_s, resolution=(W, H), spp=spp, seed=seed,
                                                      gt_rate_hz=gt_rate_hz), out_dir=out, progress=False)
    rec = tmp / f"{name or scene}.h5"
    simulate_recording(out, rec, RecordingSettings(lux=100.0, sensors={}, gt_rate_hz=gt_rate_hz))
    return rec


def _load(rec):
    with h5py.File(rec, "r") as f:
        d = {k: f[f"gt/{k}"][()] for k in ("t", "flux", "depth", "instance", "flow", "flow_valid", "velocity",
                                              "camera_to_world")}
        d["names"] = json.loads(f["gt/instance"].attrs["names"])
        d["K"] = f["camera/K"][()]
        d["camera"] = dict(f["camera"].attrs)
        if "gt/object_to_world" in f:
            d["object_to_world"] = f["gt/object_to_world"][()]
            d["objects"] = json.loads(f["gt/object_to_world"].attrs["objects"])
    return d


@pytest.fixture(scope="module")
def star(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("star")
    d = _load(_record(tmp, "siemens-star", None, duration_s=0.004))
    d["render_dir"] = tmp / "siemens-star"
    return d


def _star_truth(star, angle):
    """The star's flow for a turn by ``angle`` (rad) about +Z: the image turns by −angle about the principal
    point (camera looking down −Z with +Y up: image x is world +X, image y is world −Y)."""
    cx, cy = star["camera"]["cx_px"], star["camera"]["cy_px"]
    x, y = _pixels()
    u, v = x - cx, y - cy
    return np.stack([u * math.cos(angle) + v * math.sin(angle) - u, -u * math.sin(angle) + v * math.cos(angle) - v],
                    -1)


def test_a_slower_ground_truth_rate_gets_flow_over_its_own_interval(star, tmp_path):
    """Simulated at 500 Hz on passes rendered at 1 kHz: every instant has its pass, and the flow spans 2 ms
    (the rate `simspad simulate` takes by default is the render's)."""
    from simspad.cli.simulate import simulate_from_cli

    rec = simulate_from_cli(star["render_dir"], lux=100.0, sensors="frames", start_s=None, duration_s=None, seed=0,
                            overrides=(), out_path=tmp_path / "500.h5", gt_rate_hz=500.0)
    d = _load(rec)
    np.testing.assert_allclose(d["t"], [0.0, 0.002, 0.004])
    omega = 2 * math.pi  # 60 rpm
    on = d["instance"][0] == d["names"].index("star")
    assert np.abs(d["flow"][0][on] - _star_truth(star, omega * 0.002)[on]).max() < 1e-3
    default = _load(simulate_from_cli(star["render_dir"], lux=100.0, sensors="frames", start_s=None,
                                      duration_s=None, seed=0, overrides=(), out_path=tmp_path / "d.h5"))
    np.testing.assert_array_equal(default["flow"], star["flow"])


def _pixels():
    return np.meshgrid(np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64))


def test_star_flow_is_omega_cross_r(star):
    """Star pixels rotate about the principal point by ω·Δt; the board and stand do not move."""
    traj = tomllib.loads(find_trajectory("siemens-star.toml").read_text())["objects"]["star"]
    assert traj["axis"] == [0.0, 0.0, 1.0]
    omega = 2 * math.pi * traj["rpm"] / 60.0  # rad/s, right-handed about world +Z
    # The camera looks down world -Z with world +Y up, so image x (right) is world +X and image y (down) world -Y:
    # a turn by +ω about +Z is a turn by -ω in the image's (x, y) frame, whose velocity is (ω·v, -ω·u).
    cx, cy = star["camera"]["cx_px"], star["camera"]["cy_px"]
    x, y = _pixels()
    u, v = x - cx, y - cy
    dt = 1.0 / 1000.0
    a = omega * dt
    truth_flow = np.stack([u * math.cos(a) + v * math.sin(a) - u, -u * math.sin(a) + v * math.cos(a) - v], -1)
    truth_vel = np.stack([omega * v, -omega * u], -1)
    k_star = star["names"].index("star")
    static = (star["instance"] != k_star) & (star["instance"] != 0)
    for i in range(len(star["t"]) - 1):
        on = star["instance"][i] == k_star
        assert on.sum() > 300
        err = np.abs(star["flow"][i][on] - truth_flow[on])
        assert err.max() < 0.05, err.max()  # the bar; it holds to float32 rounding
        assert err.max() < 1e-3
        vel_err = np.abs(star["velocity"][i][on] - truth_vel[on]).max()
        assert vel_err * dt < 0.05 and vel_err < 0.05 * np.abs(truth_vel[on]).max() * 1e-2
        assert np.abs(star["flow"][i][static[i]]).max() < 1e-4
        assert np.abs(star["velocity"][i][static[i]]).max() < 1e-2
    # the largest motion is well above the tolerance, so the test can tell a wrong flow from a right one
    assert np.abs(truth_flow[star["instance"][0] == k_star]).max() > 0.1


def test_star_masks_and_intrinsics(star):
    names = star["names"]
    assert names[0] == "" and set(names[1:]) == {"board", "softbox", "stand", "star"}
    assert star["instance"].dtype == np.uint16 and star["instance"].max() < len(names)
    fx = star["camera"]["focal_px"]
    assert fx == pytest.approx((W / 2) / math.tan(math.radians(star["camera"]["x_fov_deg"]) / 2))
    np.testing.assert_allclose(star["K"], [[fx, 0, (W - 1) / 2], [0, fx, (H - 1) / 2], [0, 0, 1]])
    assert star["objects"] == ["star"] and star["object_to_world"].shape == (len(star["t"]), 1, 4, 4)
    # the last instant has no next interval in the render: its flow is undefined and nowhere valid
    assert np.isnan(star["flow"][-1]).all() and not star["flow_valid"][-1].any()
    assert star["flow_valid"][:-1].mean() > 0.95


@pytest.fixture(scope="module")
def rotation(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rotation")
    traj = tmp / "yaw.toml"
    traj.write_text('[camera]\ngenerator = "linear_pan"\nlook_at = { origin = [0.3, 1.15, 1.35], target = '
                    '[-0.1, 1.15, -0.8], up = [0.0, 1.0, 0.0] }\nyaw_rate_deg_s = 2000.0\naxis = [0.0, 1.0, 0.0]\n'
                    'duration_s = 0.01\n')
    return _load(_record(tmp, "office", traj, duration_s=0.003))


def test_pure_rotation_flow_is_the_homography(rotation):
    """A level camera turning about the vertical through its centre: x' ∝ K·R·K⁻¹·x for every pixel."""
    dt = 1.0 / 1000.0
    # Turning the camera by θ about world +Y moves a static point's camera coordinates by -θ about the camera's
    # up axis; in OpenCV's frame (y down) up is -y, so p' = R_y(+θ)·p.
    r = Rotation.from_rotvec(math.radians(2000.0) * dt * np.array([0.0, 1.0, 0.0])).as_matrix()
    K = rotation["K"]
    hom = K @ r @ np.linalg.inv(K)
    x, y = _pixels()
    p = np.stack([x, y, np.ones_like(x)], -1) @ hom.T
    truth = np.stack([p[..., 0] / p[..., 2] - x, p[..., 1] / p[..., 2] - y], -1)
    for i in range(len(rotation["t"]) - 1):
        err = np.abs(rotation["flow"][i] - truth)
        assert np.isfinite(rotation["flow"][i]).all()
        assert err.max() < 0.05, err.max()
        assert err.max() < 1e-3
    assert np.abs(truth).max() > 2.0  # 2° per interval: pixels
    # The instantaneous velocity is the homography's derivative: K·R(ε)·K⁻¹ over a 1 µs turn, per second.
    h = 1e-6
    r = Rotation.from_rotvec(math.radians(2000.0) * h * np.array([0.0, 1.0, 0.0])).as_matrix()
    p = np.stack([x, y, np.ones_like(x)], -1) @ (K @ r @ np.linalg.inv(K)).T
    truth_vel = np.stack([p[..., 0] / p[..., 2] - x, p[..., 1] / p[..., 2] - y], -1) / h
    for i in range(len(rotation["t"])):
        err = np.abs(rotation["velocity"][i] - truth_vel)
        assert err.max() < 1e-3 * np.abs(truth_vel).max(), err.max()


def _warp_residuals(d, other, i):
    """Relative RMS differences over the valid moving pixels between the image at t_i and the image at t_{i+1}
    sampled (cubic) at x + flow(x): with the flow, without it, and with the flow off by half a pixel; and over the
    flattest half of those pixels (where resampling is exact to first order), the residual with the flow and the
    render's noise (two seeds' renders of the same instant differ by √2 times one render's noise: the residual a
    perfect flow leaves, since the frozen noise stays on the screen while the content moves)."""
    x, y = _pixels()
    flow = np.nan_to_num(d["flow"][i])
    now, nxt = d["flux"][i].astype(np.float64), d["flux"][i + 1].astype(np.float64)
    moving = d["flow_valid"][i].astype(bool) & (np.hypot(flow[..., 0], flow[..., 1]) > 0.3)

    def sample(f):
        return map_coordinates(nxt, [y + f[..., 1], x + f[..., 0]], order=3, mode="nearest")

    def rms(a, sel):
        return float(np.sqrt(np.mean(a[sel] ** 2)) / now[sel].mean())

    grad = np.hypot(sobel(now, 0), sobel(now, 1)) / now.mean()
    flat = moving & (grad <= np.median(grad[moving]))
    noise = other["flux"][i].astype(np.float64) - d["flux"][i]
    off = flow + 0.5 * flow / np.hypot(flow[..., 0], flow[..., 1])[..., None].clip(1e-9)
    return {"with": rms(sample(flow) - now, moving), "without": rms(nxt - now, moving),
            "off": rms(sample(off) - now, moving), "flat_with": rms(sample(flow) - now, flat),
            "flat_noise": rms(noise, flat), "n": int(moving.sum())}


@pytest.mark.slow
@pytest.mark.parametrize("scene", ["office", "fan"])
def test_warping_by_the_flow_predicts_the_next_frame(tmp_path_factory, scene):
    """Where the mask says valid, the image at t + Δt sampled at x + flow(x) is the image at t up to the render's
    noise; the flow explains the motion (without it, or half a pixel off, the residual is larger)."""
    tmp = tmp_path_factory.mktemp(f"warp-{scene}")
    traj = None
    if scene == "office":  # the mini's ×16 hand-held pan: 0.7–1.8 px per millisecond at 64 px
        traj = retimed(load_trajectory(find_trajectory("office_handheld_pan.toml")), 16.0)
    spp = 64
    d = _load(_record(tmp, scene, traj, duration_s=0.003, spp=spp))
    other = _load(_record(tmp, scene, traj, duration_s=0.003, spp=spp, seed=1, name=f"{scene}-seed1"))
    for i in range(len(d["t"]) - 1):
        r = _warp_residuals(d, other, i)
        assert r["n"] > 100, r
        # Within the render's noise. On the office (a camera pan over a static scene) the residual is 0.75–0.93
        # of the two-seed difference (0.53–0.94 with multi-jittered samples); the fan's pitched blades turn under
        # the cage's shadows and the lights, so their brightness changes along the motion (the motion field is not
        # brightness-constancy flow), a residual the render's noise does not set: 1.4–1.9 of the two-seed
        # difference with multi-jittered samples, 1.0–1.5 with the low-discrepancy ones (noisier here).
        assert r["flat_with"] <= (1.0 if scene == "office" else 2.0) * r["flat_noise"], r
        assert r["with"] < 0.9 * r["off"], r  # the flow is the motion: half a pixel off is clearly worse
        if scene == "office":  # and it explains the images' change (the fan's blades move < 1 px per interval
            # while the frozen noise stays put, so there warping buys little over not warping at all)
            assert r["with"] < 0.75 * r["without"], r


def _independent_flow(d, i):
    """Flow from the recording's depth, K, camera and object poses, by an OpenCV-convention pinhole written here."""
    K, Kinv = d["K"], np.linalg.inv(d["K"])
    x, y = _pixels()
    z = d["depth"][i].astype(np.float64)
    p_cv = (np.stack([x, y, np.ones_like(x)], -1) @ Kinv.T) * z[..., None]
    ca, cb = d["camera_to_world"][i], d["camera_to_world"][i + 1]
    ra, rb = ca[:3, :3] @ CV, cb[:3, :3] @ CV  # OpenCV camera -> world rotations
    world = p_cv @ ra.T + ca[:3, 3]
    for k, name in enumerate(d.get("objects", [])):
        sel = d["instance"][i] == d["names"].index(name)
        m = d["object_to_world"][i + 1, k] @ np.linalg.inv(d["object_to_world"][i, k])
        world[sel] = world[sel] @ m[:3, :3].T + m[:3, 3]
    q = (world - cb[:3, 3]) @ rb
    pix = q @ K.T
    return np.stack([pix[..., 0] / pix[..., 2] - x, pix[..., 1] / pix[..., 2] - y], -1)


@pytest.fixture(scope="module")
def fan(tmp_path_factory):
    return _load(_record(tmp_path_factory.mktemp("fan"), "fan", None, duration_s=0.003))


@pytest.mark.parametrize("which", ["fan", "star"])
def test_flow_is_the_finite_difference_of_the_recorded_poses(which, request):
    d = request.getfixturevalue(which)
    for i in range(len(d["t"]) - 1):
        finite = np.isfinite(d["depth"][i])
        truth = _independent_flow(d, i)
        err = np.abs(d["flow"][i][finite] - truth[finite])
        assert err.max() < 1e-3, err.max()
    moving = d["instance"][0] == d["names"].index(d["objects"][0])
    assert np.abs(d["flow"][0][moving]).max() > 0.1  # px: well above the tolerance


def test_velocity_is_the_derivative_of_the_trajectory(fan):
    """Velocity (px/s) against a central difference of the trajectory's poses over ±1 µs, projected through K."""
    ts = load_trajectory(find_trajectory("fan.toml"))
    K = fan["K"]
    x, y = _pixels()
    k_blades = fan["names"].index("blades")
    h = 1e-6
    for i in (1, 2):  # (at t = 0 the trajectory's span begins: no central difference there)
        t = fan["t"][i]
        z = fan["depth"][i].astype(np.float64)
        cam = ts.camera.pose(t)
        p_cv = (np.stack([x, y, np.ones_like(x)], -1) @ np.linalg.inv(K).T) * z[..., None]
        world = p_cv @ (cam[:3, :3] @ CV).T + cam[:3, 3]
        sel = fan["instance"][i] == k_blades
        pix = {}
        for s in (-1, 1):
            m = ts.objects["blades"].pose(t + s * h) @ np.linalg.inv(ts.objects["blades"].pose(t))
            moved = world.copy()
            moved[sel] = moved[sel] @ m[:3, :3].T + m[:3, 3]
            c = ts.camera.pose(t + s * h)
            q = ((moved - c[:3, 3]) @ (c[:3, :3] @ CV)) @ K.T
            pix[s] = np.stack([q[..., 0] / q[..., 2], q[..., 1] / q[..., 2]], -1)
        truth = (pix[1] - pix[-1]) / (2 * h)
        finite = np.isfinite(z)
        err = np.abs(fan["velocity"][i][finite] - truth[finite])
        assert err.max() < 1e-3 * np.abs(truth[finite]).max() + 0.5, err.max()
        assert np.abs(truth[sel]).max() > 300  # px/s: the blades move


def test_validity_marks_occlusion_and_pixels_leaving_the_image(fan, rotation):
    k = fan["names"].index("blades")
    for i in range(len(fan["t"]) - 1):
        still = fan["instance"][i] != k  # the static fan body and room: flow 0
        covered = still & (fan["instance"][i + 1] == k)  # ... that a blade covers at t + Δt
        assert covered.sum() > 5
        assert not fan["flow_valid"][i][covered].any()
        assert fan["flow_valid"][i][still & ~covered].mean() > 0.99
    x, _ = _pixels()
    for i in range(len(rotation["t"]) - 1):
        land = x + rotation["flow"][i][..., 0]
        out = (land < -0.5) | (land >= W - 0.5)
        assert out.sum() > 20
        assert not rotation["flow_valid"][i][out].any()
        assert rotation["flow_valid"][i][~out].mean() > 0.9
