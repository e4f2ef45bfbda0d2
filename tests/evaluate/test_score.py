"""``simspad score``: a valid submission is scored by the protocol; every malformed kind is refused clearly."""

import h5py
import numpy as np
import pytest

from simspad.cli import main
from simspad.evaluate import metrics
from simspad.io.results_dir import read_csv
from tests.helpers.evaluation_data import gt_of, write_submission


@pytest.fixture
def dataset(evaluation_dataset):
    return evaluation_dataset


def test_valid_submission_scores_like_the_protocol(dataset, tmp_path, capsys):
    sub = write_submission(tmp_path / "sub.h5", dataset, transform=lambda f: f * 1.25)
    assert main(["score", str(sub), "--dataset", str(dataset), "--out", str(tmp_path / "res")]) == 0
    rows = read_csv(tmp_path / "res" / "results.csv")
    assert [r["recording"] for r in rows] == ["recordings/ramp/ramp_10lx.h5", "recordings/ramp/ramp_100lx.h5"]
    t, gt = gt_of(dataset / rows[0]["recording"])
    white = float(np.percentile(gt.astype(np.float64), 99))
    expected = np.mean([metrics.psnr_db(metrics.display_map(g * 1.25, white), metrics.display_map(g, white))
                        for g in gt.astype(np.float64)])
    r = rows[0]
    assert r["psnr_db"] == pytest.approx(expected, abs=1e-6)
    assert r["n_frames"] == t.size == 11
    assert (r["method"], r["bandwidth_khz_per_pixel"], r["absolute_scale"]) == ("ext", 0.5, True)
    assert (tmp_path / "res" / r["image"]).is_file()
    assert "ghost" not in (tmp_path / "res" / "results.csv").read_text()  # non-complete manifest entries skipped


def _bad(dataset, tmp_path, **kw):
    return write_submission(tmp_path / "bad.h5", dataset, **kw)


def _groups(dataset, mutate):
    t, flux = gt_of(dataset / "recordings/ramp/ramp_10lx.h5")
    members = {"t": t, "flux": flux}
    mutate(members)
    return {"ramp_10lx": members}


def _set(k, v):
    return lambda m: m.__setitem__(k, v)


MALFORMED = {
    "format": (dict(attrs={"format": "something-else"}), "/.format"),
    "missing_attr": (dict(attrs={"label": None}), "/.label"),
    "bad_bool": (dict(attrs={"absolute_scale": "maybe"}), "/.absolute_scale"),
    "negative_bandwidth": (dict(attrs={"bandwidth_khz_per_pixel": -1.0}), "/.bandwidth_khz_per_pixel"),
    "nan_bandwidth": (dict(attrs={"bandwidth_bits_per_pixel_s": float("nan")}), "/.bandwidth_bits_per_pixel_s"),
    "flux_shape": (lambda ds: dict(groups=_groups(ds, lambda m: m.__setitem__("flux", m["flux"][:, :-1]))),
                   "/ramp_10lx/flux"),
    "flux_dtype": (lambda ds: dict(groups=_groups(ds, lambda m: m.__setitem__("flux", m["flux"].astype(np.float64)))),
                   "/ramp_10lx/flux"),
    "t_dtype": (lambda ds: dict(groups=_groups(ds, lambda m: m.__setitem__("t", m["t"].astype(np.float32)))),
                "/ramp_10lx/t"),
    "t_strings": (lambda ds: dict(groups=_groups(ds, lambda m: m.__setitem__("t", np.array([b"0.0"] * 11)))),
                  "/ramp_10lx/t"),
    "t_mismatch": (lambda ds: dict(groups=_groups(ds, lambda m: m.__setitem__("t", m["t"] + 5e-4))), "/ramp_10lx/t"),
    "t_length": (lambda ds: dict(groups=_groups(ds, lambda m: m.update(t=m["t"][:-1], flux=m["flux"][:-1]))),
                 "/ramp_10lx/t"),
    "nan": (lambda ds: dict(groups=_groups(ds, lambda m: m["flux"].__setitem__((3, 2, 2), np.nan))),
            "/ramp_10lx/flux"),
    "inf": (lambda ds: dict(groups=_groups(ds, lambda m: m["flux"].__setitem__((0, 0, 0), np.inf))),
            "/ramp_10lx/flux"),
    "negative": (lambda ds: dict(groups=_groups(ds, lambda m: m["flux"].__setitem__((5, 1, 1), -1.0))),
                 "/ramp_10lx/flux"),
    "missing_flux": (lambda ds: dict(groups=_groups(ds, lambda m: m.pop("flux"))), "/ramp_10lx/flux"),
    "unknown_recording": (lambda ds: dict(groups={"office_5lx": _groups(ds, lambda m: None)["ramp_10lx"]}),
                          "/office_5lx"),
}


@pytest.mark.parametrize("kind", sorted(MALFORMED))
def test_malformed_submission_is_refused_with_a_clear_message(kind, dataset, tmp_path, capsys):
    spec, field = MALFORMED[kind]
    kwargs = spec(dataset) if callable(spec) else spec
    sub = _bad(dataset, tmp_path, **kwargs)
    code = main(["score", str(sub), "--dataset", str(dataset), "--out", str(tmp_path / "res")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and err.count("\n") == 1
    assert err.startswith("simspad: error: ") and str(sub) in err and field in err, err
    assert not (tmp_path / "res").exists() and not (tmp_path / "bad_results").exists()


def test_not_hdf5_missing_file_and_root_dataset(dataset, tmp_path, capsys):
    junk = tmp_path / "junk.h5"
    junk.write_bytes(b"\x89HDF\r\n" + bytes(100))
    root = tmp_path / "root.h5"
    with h5py.File(root, "w") as f:
        f.attrs.update(format="simspad-submission", method="m", label="m", sensors="S", absolute_scale=True,
                       bandwidth_khz_per_pixel=1.0, bandwidth_bits_per_pixel_s=1.0)
        f["flux"] = np.zeros((2, 2, 2), np.float32)
    for path, needle in ((junk, "not a readable HDF5"), (tmp_path / "none.h5", "no such submission"),
                         (root, "/flux")):
        assert main(["score", str(path), "--dataset", str(dataset)]) == 2
        err = capsys.readouterr().err
        assert needle in err and "Traceback" not in err


def test_console_script_exit_status(dataset, tmp_path, simspad_cli):
    sub = _bad(dataset, tmp_path, attrs={"format": "nope"})
    proc = simspad_cli.run("score", sub, "--dataset", dataset)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and "/.format" in proc.stderr
