"""The fuzz catalogue of tests/hostile/test_fuzz.py: a small real recording, a dataset and a submission around it,
and seeded mutations of their values, dtypes, shapes, attributes and bytes.

The base recording is simulated by SimSPAD itself (``simspad simulate`` on a 13 × 9 px render directory written
from arrays: all three sensors, ground truth with depth, poses; the width is not a multiple of 8, so SPAD padding
bits exist). Each :class:`Mutation` copies it, changes one thing with ``h5py`` and states what SimSPAD must do:
refuse the file naming ``field`` (and, for a value, the first bad index), or accept it (the controls: valid
changes that validation must not refuse). Mutations are generated from (kind, seed) pairs, so the same seeds give
the same files.
"""

from __future__ import annotations

import hashlib
import json
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import h5py
import numpy as np

H, W = 9, 13
DURATION_S = 0.012
LUX = 100.0
SEQUENCE = "rd"
KEY = f"{SEQUENCE}_{LUX:g}lx"
REC_REL = f"recordings/{SEQUENCE}/{KEY}.h5"
#: Seeds (variants) per mutation kind: 53 kinds × 5 = 265 recording mutations.
SEEDS_PER_KIND = 5


def write_base(root: Path) -> Path:
    """Simulate the base recording (``root/base.h5``) with the real pipeline (``simspad simulate``)."""
    from simspad.cli import main  # deferred: the CLI is only needed to build the fixture
    from simspad.io.render_dir import write_render_dir

    k = 13
    t = np.linspace(0.0, DURATION_S, k)
    yy, xx = np.mgrid[0:H, 0:W]
    frames = np.stack([0.2 + 0.6 * (np.sin(0.9 * (xx - 300.0 * ti)) > 0) + 0.05 * yy / H for ti in t])
    render = write_render_dir(root / SEQUENCE, t, frames.astype(np.float32), depth=np.full((k, H, W), 2.0, np.float32),
                              poses=np.repeat(np.eye(4)[None], k, axis=0)).parent
    out = root / "base.h5"
    rc = main(["simulate", str(render), "--lux", str(LUX), "--set", "frames.frame_rate_hz=400",
               "--set", "frames.max_exposure_s=1e-3", "--out", str(out)])
    assert rc == 0 and out.is_file()
    return out


def write_dataset(root: Path, recording: Path) -> Path:
    """A dataset directory ``root`` holding ``recording`` as its one complete recording (manifest with its hash)."""
    dest = root / REC_REL
    dest.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(recording, dest)
    data = dest.read_bytes()
    manifest = {"format": "simspad-dataset", "version": 1, "name": "fuzz", "spec": {}, "spec_hash": "x", "seed": 0,
                "recordings": [{"sequence": SEQUENCE, "scene": SEQUENCE, "lux": LUX, "path": REC_REL,
                                "size": len(data), "sha256": hashlib.sha256(data).hexdigest(), "status": "complete"}]}
    (root / "manifest.json").write_text(json.dumps(manifest))
    return root


def write_submission(path: Path, recording: Path, rate_hz: float = 1000.0) -> Path:
    """A valid submission for ``recording``: its ground truth at the evaluation instants (every gt instant here)."""
    with h5py.File(recording, "r") as f:
        t, flux = f["gt/t"][()], f["gt/flux"][()]
    keep = np.abs(np.round(t * rate_hz) - t * rate_hz) < 1e-6
    with h5py.File(path, "w") as f:
        f.attrs.update({"format": "simspad-submission", "method": "ext", "label": "ext (S)", "sensors": "S",
                        "absolute_scale": True, "bandwidth_khz_per_pixel": 1.0, "bandwidth_bits_per_pixel_s": 8.0})
        g = f.create_group(KEY)
        g.create_dataset("t", data=t[keep])
        g.create_dataset("flux", data=flux[keep])
    return path


@dataclass
class Mutation:
    """One mutated file: ``apply(h5, rng)`` edits it; ``field`` (None for a valid control) is what the refusal
    must name, ``index`` a fragment naming the first bad element when the mutation knows it."""

    kind: str
    seed: int
    field: str | None
    index: str | None
    apply: Callable

    @property
    def name(self) -> str:
        return f"{self.kind}-{self.seed}"

    @property
    def valid(self) -> bool:
        return self.field is None

    def write(self, base: Path, out: Path) -> Path:
        shutil.copyfile(base, out)
        with h5py.File(out, "r+") as h5:
            self.apply(h5, np.random.default_rng([self.seed, _stable(self.kind)]))
        return out


def _stable(text: str) -> int:
    return int.from_bytes(hashlib.sha256(text.encode()).digest()[:4], "little")


def _replace(h5, name: str, data) -> None:
    """Replace dataset ``name`` by ``data`` (attributes kept)."""
    attrs = dict(h5[name].attrs)
    del h5[name]
    ds = h5.create_dataset(name, data=data)
    ds.attrs.update(attrs)


def _set_item(name: str, index_fn, value_fn):
    """Set element ``index_fn(ds, rng)`` of dataset ``name`` to ``value_fn(ds, rng)``."""
    def apply(h5, rng):
        data = h5[name][()]
        data[index_fn(data, rng)] = value_fn(data, rng)
        _replace(h5, name, data)
    return apply


def _event_index(rng, n: int) -> int:
    return int(rng.integers(0, n))


# -- the catalogue: kind -> list of variants; each variant gives (field, index fragment, apply) for a seed --------

def _kinds(n_events: int, n_gt: int, n_bins: int) -> dict[str, Callable[[int], tuple]]:
    """Mutation kinds of the base recording; each maps a seed to (field, index fragment or None, apply)."""
    def pick(seed, options):
        return options[seed % len(options)]

    def ev_value(col, values, field_name=None):
        def make(seed):
            i = _event_index(np.random.default_rng([seed, _stable(col)]), n_events)
            v = pick(seed, values)
            return (f"/events/{field_name or col}", f"event {i}",
                    _set_item(f"events/{col}", lambda d, r: i, lambda d, r: v))
        return make

    def dtype_of(name, dtypes):
        def make(seed):
            dt = np.dtype(pick(seed, dtypes))
            def apply(h5, rng):
                with np.errstate(all="ignore"):  # the cast may overflow (float16, uint8): the mutation wants it
                    _replace(h5, name, h5[name][()].astype(dt))
            return (f"/{name}", None, apply)
        return make

    def attr(obj, key, values, field=None):
        def make(seed):
            v = pick(seed, values)
            def apply(h5, rng):
                target = h5 if obj == "/" else h5[obj]
                target.attrs[key] = v(h5) if callable(v) else v
            return (field or (f"/.{key}" if obj == "/" else f"/{obj}.{key}"), None, apply)
        return make

    def gt_value(name, values):
        def make(seed):
            rng = np.random.default_rng([seed, _stable(name)])
            k, r, c = int(rng.integers(0, n_gt)), int(rng.integers(0, H)), int(rng.integers(0, W))
            return (f"/{name}", f"pixel (row {r}, col {c}) of frame {k}",
                    _set_item(name, lambda d, _: (k, r, c), lambda d, _: pick(seed, values)))
        return make

    def shape_of(name, shapes):
        def make(seed):
            fn = pick(seed, shapes)
            def apply(h5, rng):
                _replace(h5, name, fn(h5[name][()]))
            return (f"/{name}", None, apply)
        return make

    def delete(names):
        def make(seed):
            name = pick(seed, names)
            def apply(h5, rng):
                del h5[name]
            return (f"/{name}", None, apply)
        return make

    def delete_attr(pairs):
        def make(seed):
            obj, key = pick(seed, pairs)
            def apply(h5, rng):
                del (h5 if obj == "/" else h5[obj]).attrs[key]
            return (f"/.{key}" if obj == "/" else f"/{obj}.{key}", None, apply)
        return make

    def ms_off(seed):
        rng = np.random.default_rng([seed, 7])
        def apply(h5, _):
            ms = h5["events/ms_to_idx"][()]
            k = int(rng.integers(0, ms.size))
            ms[k] = ms[k] + 1 if ms[k] == 0 or seed % 2 else ms[k] - 1
            _replace(h5, "events/ms_to_idx", ms)
        return ("/events/ms_to_idx", None, apply)

    def ev_unsorted(seed):
        def apply(h5, rng):
            t = h5["events/t"][()]
            i = int(rng.integers(1, t.size))
            while t[i] == t[i - 1]:
                i = int(rng.integers(1, t.size))
            t[i - 1], t[i] = t[i], t[i - 1]
            _replace(h5, "events/t", t)
        return ("/events/t", "not sorted", apply)

    def ev_t_out(seed):
        values = [-1, -(1 << 40), 1 << 62, int(DURATION_S * 1e6) + 1, (1 << 63) - 1]
        v = pick(seed, values)
        index = 0 if v < 0 else n_events - 1
        return ("/events/t", f"event {index}",
                _set_item("events/t", lambda d, r: index, lambda d, r: v))

    def gt_t_bad(seed):
        values = [np.nan, np.inf, -np.inf, DURATION_S + 1.0, -1.0]
        v = pick(seed, values)
        k = n_gt - 1 if seed % 2 else 0
        return ("/gt/t", f"index {k}", _set_item("gt/t", lambda d, r: k, lambda d, r: v))

    def gt_t_unsorted(seed):
        k = 1 + seed % (n_gt - 1)
        return ("/gt/t", f"index {k}", _set_item("gt/t", lambda d, r: k, lambda d, r: d[k - 1]))

    def spad_t_bad(seed):
        v = pick(seed, [np.nan, np.inf, DURATION_S + 0.5, -1.0, 0.0])
        k = {0.0: n_bins - 1}.get(v, int(np.random.default_rng(seed).integers(1, n_bins)))
        return ("/spad/t_start", f"index {k}", _set_item("spad/t_start", lambda d, r: k, lambda d, r: v))

    def spad_overlap(seed):
        # a bin starting inside the previous one (still increasing): bins are [t_start, t_start + bin_s)
        k = 1 + int(np.random.default_rng([seed, 17]).integers(0, n_bins - 1))
        step = pick(seed, [1e-6, 5e-6, 1e-5, 1e-9, 2e-6])
        return ("/spad/t_start", f"index {k}", _set_item("spad/t_start", lambda d, r: k, lambda d, r: d[k - 1] + step))

    def spad_padding(seed):
        rng = np.random.default_rng([seed, 3])
        m, r = int(rng.integers(0, n_bins)), int(rng.integers(0, H))
        bit = int(rng.integers(W % 8, 8))
        return ("/spad/bits", f"index {m}, row {r}",
                _set_item("spad/bits", lambda d, _: (m, r, -1), lambda d, _: d[m, r, -1] | (1 << bit)))

    def dcr_bad(seed):
        rng = np.random.default_rng([seed, 13])
        r, c = int(rng.integers(0, H)), int(rng.integers(0, W))
        return ("/spad/dcr_cps", f"pixel (row {r}, col {c})", _set_item(
            "spad/dcr_cps", lambda d, _: (r, c), lambda d, _: pick(seed, [np.nan, -1.0, np.inf, -5.0, -np.inf])))

    def frames_dn(seed):
        rng = np.random.default_rng([seed, 5])
        return ("/frames/dn", "of frame", _set_item(
            "frames/dn", lambda d, _: (int(rng.integers(0, d.shape[0])), int(rng.integers(0, H)),
                                       int(rng.integers(0, W))),
            lambda d, _: pick(seed, [4096, 65535, 5000, 40000, 4097])))

    def frames_t(seed):
        def apply(h5, rng):
            ts, te = h5["frames/t_start"][()], h5["frames/t_end"][()]
            k = int(rng.integers(0, ts.size))
            if seed % 3 == 0:
                te[k] = ts[k]
            elif seed % 3 == 1:
                te[k] = np.nan
            else:
                te[k] = DURATION_S + 1.0
            _replace(h5, "frames/t_end", te)
        return ("/frames/t_end", None, apply)

    def poses_bad(seed):
        rng = np.random.default_rng([seed, 11])
        k = int(rng.integers(0, n_gt))
        return ("/poses/camera_to_world", f"of pose {k}",
                _set_item("poses/camera_to_world", lambda d, _: (k, 0, 3), lambda d, _: pick(seed, [np.nan, np.inf])))

    def bytes_flip(seed):
        # garbage written straight into the file where a dataset's bytes lie (contiguous events, or a zstd chunk)
        name = pick(seed, ["events/t", "events/x", "spad/bits", "events/p", "gt/flux"])
        field = f"/{name}"

        def apply(h5, rng):
            ds = h5[name]
            offset = ds.id.get_offset() if ds.chunks is None else ds.id.get_chunk_info(0).byte_offset
            size = ds.id.get_storage_size() if ds.chunks is None else ds.id.get_chunk_info(0).size
            garbage = rng.integers(0, 256, min(size, 64), dtype=np.uint8).tobytes()
            h5.flush()
            with open(h5.filename, "r+b") as raw:
                # a compressed chunk from its first byte (the Zstandard frame header): undecodable
                raw.seek(offset if ds.compression or ds.id.get_create_plist().get_nfilters() else
                         offset + int(rng.integers(0, max(1, size - len(garbage)))))
                raw.write(b"\xff" * 8 + garbage)
        return (field, None, apply)

    def group_as_dataset(seed):
        group = pick(seed, ["events", "spad", "frames", "gt", "poses"])
        def apply(h5, rng):
            del h5[group]
            h5.create_dataset(group, data=np.zeros(3))
        return (f"/{group}", None, apply)

    def dataset_as_group(seed):
        name = pick(seed, ["events/x", "gt/flux", "spad/bits", "frames/dn", "events/ms_to_idx"])
        def apply(h5, rng):
            del h5[name]
            h5.create_group(name)
        return (f"/{name}", None, apply)

    def link(seed):
        name = pick(seed, ["events/t", "gt/flux", "spad/bits"])
        def apply(h5, rng):
            del h5[name]
            if seed % 2:
                h5[name] = h5py.SoftLink("/gt/t")
            else:
                h5[name] = h5py.ExternalLink("/etc/passwd", "/x")
        return (f"/{name}", None, apply)

    def not_stored(seed):
        # a dataset declared huge in a tiny file: its chunks are never written (they would read as zeros)
        name, shape, chunks = pick(seed, [("events/t", (1 << 40,), (1 << 16,)), ("events/x", (10**12,), (4096,)),
                                          ("gt/flux", (10**7, H, W), (16, H, W)),
                                          ("spad/bits", (10**8, H, 2), None), ("spad/t_start", (10**9,), None)])

        def apply(h5, rng):
            dtype = h5[name].dtype
            del h5[name]
            h5.create_dataset(name, shape=shape, dtype=dtype, chunks=chunks)
        return (f"/{name}", None, apply)

    # Valid controls: what a well-formed file may hold; validation must accept them.
    def valid(seed):
        options = [
            _set_item("events/x", lambda d, r: _event_index(r, d.size), lambda d, r: W - 1),
            _set_item("events/p", lambda d, r: _event_index(r, d.size), lambda d, r: 1 - d[_event_index(r, d.size)]),
            _set_item("gt/flux", lambda d, r: (0, 0, 0), lambda d, r: 0.0),
            lambda h5, r: h5.attrs.__setitem__("user_note", "an attribute SimSPAD does not know"),
            lambda h5, r: h5.create_dataset("extra/thing", data=np.arange(3)),
        ]
        return (None, None, pick(seed, options))

    return {
        # event values
        "events_x_outside": ev_value("x", [W, 65535, W + 1, 1000, 32768]),
        "events_y_outside": ev_value("y", [H, 65535, H + 7, 255, 60000]),
        "events_p_not_0_1": ev_value("p", [7, 2, 255, 128, 3]),
        "events_label_not_0_3": ev_value("label", [4, 255, 9, 100, 5]),
        "events_t_outside_span": ev_t_out,
        "events_t_unsorted": ev_unsorted,
        "events_ms_to_idx_wrong": ms_off,
        # event dtypes and shapes
        "events_t_dtype": dtype_of("events/t", ["float64", "int32", ">i8", "uint64", "float32"]),
        "events_x_dtype": dtype_of("events/x", ["int64", "uint32", "int16", "float32", ">u2"]),
        "events_p_dtype": dtype_of("events/p", ["int8", "bool", "float64", "uint16", "int64"]),
        "events_ms_dtype": dtype_of("events/ms_to_idx", ["int64", "uint32", "float64", ">u8", "int32"]),
        "events_length": shape_of("events/x", [lambda d: d[:-1], lambda d: d[:0], lambda d: np.r_[d, d[:3]],
                                               lambda d: d[None], lambda d: d[:5]]),
        # ground truth
        "gt_t_not_finite_or_outside": gt_t_bad,
        "gt_t_unsorted": gt_t_unsorted,
        "gt_flux_not_finite_or_negative": gt_value("gt/flux", [np.nan, -1.0, np.inf, -np.inf, -1e-30]),
        "gt_depth_nan_or_negative": gt_value("gt/depth", [np.nan, -1.0, -np.inf, -0.5, np.nan]),
        "gt_flux_shape": shape_of("gt/flux", [lambda d: d[:0], lambda d: d[:, :, :-1], lambda d: d[:-1],
                                              lambda d: d[0], lambda d: np.concatenate([d, d[:1]])]),
        "gt_flux_dtype": dtype_of("gt/flux", ["float64", "float16", "int32", ">f4", "uint16"]),
        "gt_t_dtype": dtype_of("gt/t", ["float32", "int64", ">f8", "float16", "uint8"]),
        # SPAD
        "spad_bits_dtype": dtype_of("spad/bits", ["float64", "uint16", "bool", "int8", "float32"]),
        "spad_bits_shape": lambda s: (r"/spad/(bits|t_start)",) + shape_of("spad/bits", [
            lambda d: d[:, :, :1], lambda d: d[:, :-1], lambda d: np.concatenate([d, d[:, :, :1]], axis=2),
            lambda d: d[:-1], lambda d: d[:, :, 0]])(s)[1:],
        "spad_padding_bits": spad_padding,
        "spad_t_start_bad": spad_t_bad,
        "spad_dcr_bad": dcr_bad,
        "spad_attr_bad": lambda s: attr("spad", pick(s, ["bin_s", "gate_s", "qe", "fill_factor", "pixel_pitch_m"]),
                                        [0.0, -1.0, np.nan, "abc", np.array([1.0, 2.0])])(s),
        "spad_gate_longer_than_bin": attr("spad", "gate_s", [1.0, 2e-5, 1e-3, 0.5, 3e-5]),
        "spad_bins_overlap": spad_overlap,
        # frames
        "frames_dn_over_adc": frames_dn,
        "frames_dn_dtype": dtype_of("frames/dn", ["float32", "int32", "uint8", ">u2", "int64"]),
        "frames_exposure_bad": frames_t,
        "frames_bit_depth_bad": attr("frames", "bit_depth", [0, 17, 99, "12", 12.5]),
        # events attributes
        "events_threshold_bad": lambda s: attr("events", pick(s, ["threshold_on", "threshold_off"]),
                                               [0.0, -0.3, np.nan, "x", np.inf])(s),
        "events_n_events_mismatch": attr("events", "n_events", [0, 1, -1, 10**9, 438]),
        # root attributes
        "root_width_bad": attr("/", "width", [0, -5, "abc", 1.5, 70000]),
        "root_height_bad": attr("/", "height", [0, -1, "9", np.nan, 100000]),
        "root_width_mismatch": lambda s: (r"/(gt|spad|frames)/\w+", None,
                                          attr("/", "width", [W - 1, W + 1, W + 8, 1, 64])(s)[2]),
        "root_duration_bad": attr("/", "duration_s", [0.0, -1.0, np.nan, "1", 1e9]),
        "root_lux_bad": attr("/", "lux", [0.0, -1.0, np.nan, "x", np.array([1.0, 2.0])]),
        "root_span_bad": lambda s: attr("/", pick(s, ["t_start_s", "t_end_s"]),
                                        [-1.0, np.nan, -0.5, 0.0, np.inf])(s),
        "root_time_origin_bad": attr("/", "time_origin_s", [0.5, -1.0, np.nan, "0", 1e9]),
        "root_spec_bad": attr("/", "spec", ["{", "[1]", '{"evaluation": {"rate_hz": "fast"}}',
                                            '{"evaluation": {"rate_hz": 0}}', '{"evaluation": []}']),
        "root_sensors_mismatch": attr("/", "sensors", ["spad", "spad,frames", "events,frames", "", "spad,frames,x"]),
        "root_format_version": attr("/", "format_version", [2, "1", 0, 1.5, -1], field="/.format_version"),
        "root_attr_unreadable": attr("/", "width", [lambda h5: h5["gt"].ref, lambda h5: h5["gt"].ref,
                                                    lambda h5: h5["gt"].ref, lambda h5: h5["gt"].ref,
                                                    lambda h5: h5["gt"].ref]),
        # structure
        "dataset_missing": delete(["events/ms_to_idx", "gt/t", "spad/dcr_cps", "frames/t_end", "poses/t"]),
        "attr_missing": delete_attr([("/", "width"), ("spad", "bin_s"), ("events", "threshold_on"),
                                     ("frames", "bit_depth"), ("/", "lux")]),
        "group_as_dataset": group_as_dataset,
        "dataset_as_group": dataset_as_group,
        "link_instead_of_dataset": link,
        "poses_not_finite": poses_bad,
        "bytes_overwritten": bytes_flip,
        "dataset_declared_not_stored": not_stored,
        "valid_control": valid,
    }


def recording_mutations(base: Path) -> list[Mutation]:
    """Every recording mutation: each kind × :data:`SEEDS_PER_KIND` seeds."""
    with h5py.File(base, "r") as f:
        n_events, n_gt, n_bins = f["events/t"].shape[0], f["gt/t"].shape[0], f["spad/bits"].shape[0]
    out = []
    for kind, make in _kinds(n_events, n_gt, n_bins).items():
        for seed in range(SEEDS_PER_KIND):
            field, index, apply = make(seed)
            out.append(Mutation(kind, seed, field, index, apply))
    return out


def submission_mutations() -> list[Mutation]:
    """Mutations of the valid submission (``simspad score``): attributes, dtypes, shapes, values, structure."""
    def attr(key, value):
        return lambda h5, rng: h5.attrs.__setitem__(key, value)

    def member(name, fn):
        def apply(h5, rng):
            data = fn(h5[f"{KEY}/{name}"][()], rng)
            del h5[f"{KEY}/{name}"]
            h5[KEY].create_dataset(name, data=data)
        return apply

    def nan_at(d, rng):
        d = d.copy()
        d.reshape(-1)[int(rng.integers(0, d.size))] = np.nan
        return d

    def corrupt_flux(h5, rng):
        data = h5[f"{KEY}/flux"][()]
        del h5[f"{KEY}/flux"]
        ds = h5[KEY].create_dataset("flux", data=data, chunks=(1, *data.shape[1:]), compression="gzip")
        info = ds.id.get_chunk_info(0)
        h5.flush()
        with open(h5.filename, "r+b") as raw:
            raw.seek(info.byte_offset)
            raw.write(b"\xff" * min(16, info.size))

    cases = [
        ("/.method", lambda h5, rng: h5.attrs.__delitem__("method")),
        ("/.absolute_scale", attr("absolute_scale", "maybe")),
        ("/.bandwidth_khz_per_pixel", attr("bandwidth_khz_per_pixel", -1.0)),
        ("/.bandwidth_bits_per_pixel_s", attr("bandwidth_bits_per_pixel_s", np.nan)),
        ("/.bandwidth_khz_per_pixel", attr("bandwidth_khz_per_pixel", "fast")),
        ("/.label", attr("label", np.array([1, 2]))),
        ("/.format", attr("format", "simspad-recording")),
        ("/.format_version", attr("format_version", 2)),
        (f"/{KEY}/t", member("t", lambda d, r: d.astype(np.float32))),
        (f"/{KEY}/t", member("t", nan_at)),
        (f"/{KEY}/t", member("t", lambda d, r: d + 1e-3)),
        (f"/{KEY}/t", member("t", lambda d, r: d[:-1])),
        (f"/{KEY}/t", member("t", lambda d, r: d.astype(">f8"))),
        (f"/{KEY}/flux", member("flux", nan_at)),
        (f"/{KEY}/flux", member("flux", lambda d, r: -d)),
        (f"/{KEY}/flux", member("flux", lambda d, r: d.astype(np.float64))),
        (f"/{KEY}/flux", member("flux", lambda d, r: d[:, :-1])),
        (f"/{KEY}/flux", member("flux", lambda d, r: d[:-1])),
        (f"/{KEY}/flux", member("flux", lambda d, r: d.astype(">f4"))),
        (f"/{KEY}/flux", member("flux", lambda d, r: np.full(d.shape, np.inf, np.float32))),
        (f"/{KEY}/extra", lambda h5, rng: h5[KEY].create_dataset("extra", data=np.zeros(2))),
        ("/loose", lambda h5, rng: h5.create_dataset("loose", data=np.zeros(2))),
        ("/other_1lx", lambda h5, rng: h5.move(KEY, "other_1lx")),
        (f"/{KEY}/flux", lambda h5, rng: (h5[KEY].__delitem__("flux"),
                                           h5[KEY].__setitem__("flux", h5py.SoftLink(f"/{KEY}/t")))),
        (f"/{KEY}/flux", corrupt_flux),
        (None, lambda h5, rng: h5.attrs.__setitem__("note", "an extra attribute")),
    ]
    return [Mutation("submission", i, field, None, apply) for i, (field, apply) in enumerate(cases)]
