"""A recording stores its inputs' paths relative to the spec's folder: same spec, same bytes from any checkout."""

from __future__ import annotations

import json
import shutil

from simspad.bundled import TRAJECTORIES_DIR
from simspad.dataset.plan import make_plan
from simspad.dataset.spec_validation import load_spec


def test_recording_metadata_does_not_depend_on_the_checkout_path(tmp_path):
    metas = []
    for where in ("checkout_a", "deeper/checkout_b"):
        folder = tmp_path / where
        folder.mkdir(parents=True)
        shutil.copy(TRAJECTORIES_DIR / "siemens-star.toml", folder / "spin.toml")
        (folder / "spec.toml").write_text('name = "p"\nlux = [10]\n[[sequences]]\nscene = "siemens-star"\n'
                                          'trajectory = "spin.toml"\nduration_s = 0.01\nresolution = [16, 12]\n')
        plan = make_plan(load_spec(folder / "spec.toml"), "2025-01-01T00:00:00Z")
        metas.append(dict(plan.recordings[0].metadata))
    assert metas[0] == metas[1]
    assert metas[0]["trajectory"] == "spin.toml"
    assert json.loads(metas[0]["spec"])["sequence"]["trajectory"] == "spin.toml"
    assert str(tmp_path) not in json.dumps(metas[0])
