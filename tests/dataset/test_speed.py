"""The speed axis of a dataset: spec checks, refusal past a trajectory's coverage, names and seeds per speed, a
spec without ``speed`` planned exactly as before, and a k× recording whose poses are the base trajectory at k·t
and whose measured image motion is stated in its attributes."""

from __future__ import annotations

import json
import re
import shutil

import h5py
import numpy as np
import pytest

from simspad.bundled import TRAJECTORIES_DIR
from simspad.dataset.estimate import (
    SceneRenderCost,
    UnitCosts,
    disk_needed_bytes,
    estimate_spec,
)
from simspad.dataset.executors import ExecutorConfig, render_layout_of
from simspad.dataset.generate import generate
from simspad.dataset.plan import make_plan
from simspad.dataset.spec_validation import load_spec
from simspad.errors import SpecError
from simspad.io.manifest import read_manifest
from simspad.io.trajectory_files import load_trajectory

MOTION_ATTRS = ("speed_factor", "image_speed_px_s_p50", "image_speed_px_s_p95", "frame_blur_px_p95")


def _spec(tmp_path, speed_line: str, *, duration_s=0.05, resolution=(80, 60), sensors="", start_s=0.0,
          name="spec.toml") -> object:
    path = tmp_path / name
    path.write_text(f"""
name = "s"
seed = 3
output = "{tmp_path / 'out'}"
lux = [10, 100]
{speed_line}

[[sequences]]
scene = "office"
duration_s = {duration_s}
start_s = {start_s}
resolution = [{resolution[0]}, {resolution[1]}]
spp = 1

[[sequences]]
scene = "fan"
duration_s = {duration_s}
start_s = {start_s}
resolution = [{resolution[0]}, {resolution[1]}]
spp = 1
{sensors}
""")
    return path


def test_spec_without_speed_plans_exactly_as_speed_one(tmp_path):
    plain = make_plan(load_spec(_spec(tmp_path, "")), "2025-01-01T00:00:00Z")
    one = make_plan(load_spec(_spec(tmp_path, "speed = [1.0]")), "2025-01-01T00:00:00Z")
    assert plain == one
    assert [r.rel_path for r in plain.recordings][:2] == ["recordings/office/office_10lx.h5",
                                                          "recordings/office/office_100lx.h5"]
    assert all("speed_factor" not in dict(r.metadata) for r in plain.recordings)


def test_disk_check_counts_every_speed_and_skips_recordings_already_there(tmp_path):
    sensors = '[sensors.spad]\npreset = "swissspad2"\n[sensors.frames]\npreset = "blackfly_s"\n'
    one = load_spec(_spec(tmp_path, "", sensors=sensors))
    both = load_spec(_spec(tmp_path, "speed = [1, 8]", sensors=sensors))
    out = tmp_path / "ds"
    need_one, need_both = disk_needed_bytes(one, out), disk_needed_bytes(both, out)
    w, h = 80, 60
    gt = both.evaluation.rate_hz * 0.05 * w * h * 8  # flux and depth, float32 each
    spad_p, frame_p = both.sensors["spad"].params, both.sensors["frames"].params
    spad = 0.05 / spad_p.bin_s * h * (w // 8)  # one bit per pixel and bin, uncompressed
    frames = 0.05 * frame_p.frame_rate_hz * w * h * 2
    assert abs(need_one - 2 * 2 * (gt + spad + frames)) <= 1  # 2 sequences × 2 lux levels
    assert abs(need_both - 2 * need_one) <= 1
    # A recording already written is not counted again, whatever its speed.
    rel = make_plan(both, "2025-01-01T00:00:00Z").recordings[-1].rel_path
    assert "_x8_" in rel
    (out / rel).parent.mkdir(parents=True)
    (out / rel).write_bytes(b"")
    assert abs(disk_needed_bytes(both, out) - (need_both - (gt + spad + frames))) <= 1


def test_each_speed_gets_its_own_render_names_and_seeds(tmp_path):
    plain = make_plan(load_spec(_spec(tmp_path, "")), "2025-01-01T00:00:00Z")
    both = make_plan(load_spec(_spec(tmp_path, "speed = [1, 8]")), "2025-01-01T00:00:00Z")
    assert len(both.renders) == 4 and len(both.recordings) == 8
    ones = [r for r in both.recordings if r.speed_factor == 1.0]
    assert ones == list(plain.recordings)  # factor 1 untouched by the presence of other speeds
    fast = [r for r in both.recordings if r.speed_factor == 8.0]
    assert [r.rel_path for r in fast[:2]] == ["recordings/office/office_x8_10lx.h5",
                                              "recordings/office/office_x8_100lx.h5"]
    assert fast[0].settings.stream_key == ("office", 10.0, "speed", 8.0)
    assert dict(fast[0].metadata)["speed_factor"] == 8.0
    fast_render = next(r for r in both.renders if r.rel_dir == fast[0].render_rel_dir)
    base_render = both.renders[0]
    assert fast_render.rel_dir.startswith("renders/office_x8-")
    # ×8 from t = 0 passes through ×1's poses: it shares ×1's keyframes, so it takes ×1's seed (same pixels)
    assert fast_render.prefix == base_render and fast_render.seed == base_render.seed
    assert fast_render.render_hash != base_render.render_hash
    # from a later start the speeds play different parts of the trajectory: nothing shared, seeds of their own
    late = make_plan(load_spec(_spec(tmp_path, "speed = [1, 8]", start_s=0.01, name="late.toml")),
                     "2025-01-01T00:00:00Z").renders
    assert late[1].speed_factor == 8.0 and late[1].prefix is None and late[1].seed != late[0].seed
    assert len({r.recording_hash for r in both.recordings}) == 8


def test_speeds_chain_their_shared_keyframes(tmp_path):
    """With three speeds each render starts with the next slower one's keyframes (×4 with ×2's, which start with
    ×1's), at instants scaled by the speed ratio, and renders only the rest of its span."""
    spec = load_spec(_spec(tmp_path, "speed = [4, 1, 2]", duration_s=0.01, resolution=(24, 18)))
    renders = {r.speed_factor: r for r in make_plan(spec, "2025-01-01T00:00:00Z").renders
               if r.sequence.scene == "office"}
    planned = {}
    plans = {k: planned.setdefault(renders[k].rel_dir, render_layout_of(renders[k], planned)) for k in (1.0, 2.0, 4.0)}
    assert renders[4.0].prefix == renders[2.0] and renders[2.0].prefix == renders[1.0]
    for slow, fast in ((1.0, 2.0), (2.0, 4.0)):
        n = plans[slow].n_keyframes
        assert plans[fast].n_shared == n and plans[fast].names[:n] == plans[slow].names
        assert plans[fast].times_s[:n] == tuple(t * slow / fast for t in plans[slow].times_s)
        assert plans[fast].times_s[-1] == pytest.approx(0.01) and plans[fast].n_keyframes > n
        assert plans[fast].timeline["schedule"]["n_rendered_keyframes"] == plans[fast].n_keyframes - n


@pytest.mark.parametrize("line, message", [
    ("speed = [1, 1.0]", "speed[1]: duplicate speed factor"),
    ("speed = [0]", "speed[0]: must be > 0"),
    ("speed = []", "speed: got list"),
    ('speed = ["fast"]', "speed[0]: got string"),
])
def test_bad_speed_refused_naming_the_field(tmp_path, line, message):
    with pytest.raises(SpecError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_spec(_spec(tmp_path, line))


def test_factor_past_coverage_refused_naming_sequence_and_coverage(tmp_path, simspad_cli):
    # office.toml and fan.toml cover 0–2 s: 0.05 s at ×50 would play 0–2.5 s
    path = _spec(tmp_path, "speed = [1, 50]")
    with pytest.raises(SpecError) as info:
        load_spec(path)
    text = info.value.format()
    assert "sequence 'office'" in text and "sequence 'fan'" in text
    assert "plays 0–2.5 s" in text and "covers 0–2 s" in text and "factor ≤ 40" in text
    done = simspad_cli.run("info", path)  # `simspad info SPEC` refuses it before any work
    assert done.returncode == 2, done.stderr
    assert "sequence 'office'" in done.stderr and "covers 0–2 s" in done.stderr
    assert "Traceback" not in done.stderr


@pytest.mark.slow
def test_fast_recording_plays_base_trajectory_at_k_t_and_states_its_motion(tmp_path, capsys):
    k = 4.0
    spec = load_spec(_spec(tmp_path, f"speed = [1, {k:g}]", duration_s=0.004, resolution=(24, 18),
                           sensors='[sensors.frames]\npreset = "blackfly_s"\nframe_rate_hz = 1000.0\n'
                                   'exposure_s = 0.0005'))
    result = generate(spec, tmp_path / "out", ExecutorConfig(workers=1), progress=True,
                      created_utc="2025-01-01T00:00:00Z")
    progress_text = capsys.readouterr().err
    base = load_trajectory(TRAJECTORIES_DIR / "office.toml")
    measured = {}
    for speed, name in ((1.0, "office_10lx.h5"), (k, f"office_x{k:g}_10lx.h5")):
        with h5py.File(result.out_dir / "recordings" / "office" / name, "r") as f:
            t = f["poses/t"][()]
            np.testing.assert_allclose(f["poses/camera_to_world"][()], base.camera.pose(speed * t), rtol=0,
                                       atol=1e-9)
            assert f.attrs["speed_factor"] == speed
            assert f.attrs["frame_blur_exposure_s"] == pytest.approx(0.0005)
            measured[speed] = {a: float(f.attrs[a]) for a in MOTION_ATTRS}
    # a hand-held camera k× faster plays k× more of its (irregular) path: it moves and blurs more
    assert measured[k]["image_speed_px_s_p50"] > measured[1.0]["image_speed_px_s_p50"] > 0
    assert measured[k]["frame_blur_px_p95"] > measured[1.0]["frame_blur_px_p95"] > 0
    # the fan's blades spin at a constant rate on their own (static camera): the measurement follows the objects,
    # and k× the spin is k× the blade speed
    fan = {}
    for speed, name in ((1.0, "fan_10lx.h5"), (k, f"fan_x{k:g}_10lx.h5")):
        with h5py.File(result.out_dir / "recordings" / "fan" / name, "r") as f:
            fan[speed] = float(f.attrs["image_speed_px_s_p95"])
    assert fan[1.0] > 100.0
    assert fan[k] == pytest.approx(k * fan[1.0], rel=0.15)
    entries = {e["path"]: e for e in read_manifest(result.out_dir)["recordings"]}
    entry = entries[f"recordings/office/office_x{k:g}_10lx.h5"]
    assert entry["speed_factor"] == k and entry["motion"]["image_speed_px_s_p95"] > 0

    # ×4 passes through ×1's poses in a quarter of the time: its first keyframes are ×1's files, hard-linked.
    out = result.out_dir
    renders = make_plan(spec, "2025-01-01T00:00:00Z").renders
    timelines = {r.rel_dir: json.loads((out / r.rel_dir / "timeline.json").read_text()) for r in renders}
    fast_frames = {}
    for slow, fast in ((renders[0], renders[1]), (renders[2], renders[3])):
        assert fast.prefix == slow
        s_kf, f_kf = timelines[slow.rel_dir]["keyframes"], timelines[fast.rel_dir]["keyframes"]
        shared = timelines[fast.rel_dir]["schedule"]["shared_keyframes"]
        assert shared == {"n_keyframes": len(s_kf), "time_scale": 0.25} and len(f_kf) > len(s_kf)
        for a, b in zip(s_kf, f_kf):
            assert b["t"] == a["t"] / 4 and b["camera_to_world"] == a["camera_to_world"] and b["file"] == a["file"]
            assert (out / fast.rel_dir / b["file"]).samefile(out / slow.rel_dir / a["file"])
        if fast.sequence.scene == "office":  # every pose, shared or not, is the retimed trajectory's at its t
            np.testing.assert_allclose([kf["camera_to_world"] for kf in f_kf],
                                       base.camera.pose(k * np.array([kf["t"] for kf in f_kf])), rtol=0, atol=1e-9)
        fast_frames[fast.rel_dir] = {kf["file"]: (out / fast.rel_dir / kf["file"]).read_bytes() for kf in f_kf}
    for r in renders:  # a render directory holds its timeline, keyframes, noise probe and geometry passes, nothing else
        files = {p.relative_to(out / r.rel_dir).as_posix() for p in (out / r.rel_dir).rglob("*")}
        frames = {kf["file"] for kf in timelines[r.rel_dir]["keyframes"]}
        geometry = {g["file"] for g in timelines[r.rel_dir]["geometry"]["instants"]}
        assert len(geometry) == round(timelines[r.rel_dir]["duration_s"] * 1000) + 1  # one per ground-truth instant
        expected = ({"timeline.json", "frames", "geometry", timelines[r.rel_dir]["render_noise"]["probe_file"]}
                    | frames | geometry)
        assert files == expected, sorted(files ^ expected)[:5]

    # The estimate plans each render as generate does: retimed (the spinning fan at ×4 needs more keyframes, its
    # blades move 4× farther per second), counting only what is rendered, not what is shared.
    unit = SceneRenderCost(a_s=1.0, b_s=0.0, exr_bytes_per_px=12.0, rss_bytes_per_mp_spp=None, process_rss_bytes=None)
    est = estimate_spec(spec, UnitCosts(render={"office": unit, "fan": unit}))
    rendered = {r["path"]: r["n_keyframes"] for r in read_manifest(out)["renders"]}
    shared = {r.rel_dir: len(timelines[r.prefix.rel_dir]["keyframes"]) if r.prefix else 0 for r in renders}
    assert [n for _, n in est.keyframe_s] == [rendered[r.rel_dir] - shared[r.rel_dir] for r in renders]
    assert est.n_shared_keyframes == sum(shared.values()) > 0
    assert rendered[renders[3].rel_dir] > 2 * rendered[renders[2].rel_dir]  # fan ×4 against fan ×1
    # The keyframe bar's total counts what is rendered (one worker: every plan is made before any keyframe, so
    # the slower renders are still running then); the shared keyframes join it as they are linked.
    shown = [(int(n), int(t)) for n, t in re.findall(r"keyframes:[^\r\n]*?(\d+)/(\d+)", progress_text)]
    totals = [t for _, t in shown]
    n_all = sum(len(t["keyframes"]) for t in timelines.values())
    assert sum(rendered.values()) - sum(shared.values()) in totals
    assert totals == sorted(totals) and shown[-1] == (n_all, n_all)
    assert all(n <= t for n, t in shown)

    # Without the slower render's files (deleted; its recordings stay complete, so it is not rendered again) the
    # faster render renders its shared keyframes itself, on 2 workers: the same bytes as the linked files.
    for r in renders:
        shutil.rmtree(out / r.rel_dir)
    for rec in make_plan(spec, "2025-01-01T00:00:00Z").recordings:
        if rec.speed_factor == k:
            (out / rec.rel_path).unlink()
    generate(spec, out, ExecutorConfig(workers=2), progress=False, created_utc="2025-01-01T00:00:00Z")
    for r in renders:
        assert (out / r.rel_dir).exists() == (r.speed_factor == k)
    for rel, frames in fast_frames.items():
        for name, data in frames.items():
            assert (out / rel / name).read_bytes() == data
