"""Fuzzing the inputs: every mutated recording or submission is refused in one line naming the file and the field
(exit 2), or accepted when it is still valid; never a signal, a traceback or an internal error (issue 33).

Two stages, so that the suite stays inside its budget:

1. in this process, every mutation of :mod:`tests.hostile.fuzz_cases` (≥ 200: values, dtypes, shapes, attributes,
   structure, raw bytes; seeded) is opened with :func:`simspad.open_recording`, which must refuse the invalid ones
   naming the mutated field (and the first bad index where the mutation knows it) and accept the valid controls;
2. in one child process (:mod:`tests.hostile.fuzz_driver`), a stratified subset — the first seed of every
   mutation kind, every valid control and every submission mutation — goes through the command line itself:
   ``info``, ``evaluate`` (every method the recording allows), ``score`` and ``export`` to every format.
   On the shared 2-core machine (load average 7–11) this stage took 10–30 s of wall time, about 8 s of CPU;
   the whole file 20–50 s.

A few headline findings of issue 33 also run as separate ``simspad`` processes, whose exit status shows a signal.
"""

from __future__ import annotations

import json
import re
import subprocess
import sys

import h5py
import numpy as np
import pytest

from simspad.errors import InputError
from simspad.io.export import FORMATS
from simspad.io.recording import open_recording
from tests.conftest import REPO
from tests.hostile import fuzz_cases
from tests.hostile.fuzz_cases import REC_REL, write_base, write_dataset, write_submission

pytestmark = pytest.mark.slow
_SUFFIX = {"dsec": ".h5", "aedat4": ".aedat4", "evt3": ".raw", "npz": "", "dsec-flow": ""}


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz")
    return write_base(root)


def _field_pattern(field: str) -> str:
    return field if "(" in field else re.escape(field)


def test_every_mutation_is_refused_naming_its_field_or_accepted(base, tmp_path):
    mutations = fuzz_cases.recording_mutations(base)
    assert len(mutations) >= 200 and len({m.kind for m in mutations}) >= 40
    outcomes = {"refused": 0, "accepted": 0}
    for i, m in enumerate(mutations):
        path = m.write(base, tmp_path / f"{i:03d}.h5")
        try:
            with open_recording(path):
                pass
        except InputError as exc:
            outcomes["refused"] += 1
            assert not m.valid, f"{m.name}: a valid file was refused: {exc}"
            text = str(exc)
            assert text.startswith(f"{path}: ") and "\n" not in text, f"{m.name}: {text}"
            assert re.match(_field_pattern(m.field), exc.field or ""), f"{m.name}: expected {m.field}: {text}"
            assert m.index is None or m.index in text, f"{m.name}: expected {m.index!r} in {text}"
        else:
            outcomes["accepted"] += 1
            assert m.valid, f"{m.name}: invalid value accepted silently (expected a refusal naming {m.field})"
        path.unlink()
    print(f"fuzz stage 1: {len(mutations)} recording mutations of {len({m.kind for m in mutations})} kinds: "
          f"{outcomes}")


def _jobs(base, tmp_path) -> tuple[list[dict], dict]:
    """The CLI stage's jobs and, per job name, the field its refusal must name (None: must succeed)."""
    jobs, expect = [], {}
    # one of each kind, and every valid control
    recording_muts = [m for m in fuzz_cases.recording_mutations(base) if m.seed == 0 or m.valid]
    base_sub = write_submission(tmp_path / "base_sub.h5", base)
    for m in recording_muts:
        d = tmp_path / m.name
        d.mkdir()
        rec = m.write(base, d / "rec.h5")
        dataset = write_dataset(d / "dataset", rec)
        sub = write_submission(d / "sub.h5", rec) if m.valid else base_sub
        commands = {"info": ["info", rec], "evaluate": ["evaluate", rec, "--out", d / "eval"],
                    "score": ["score", sub, "--dataset", dataset, "--out", d / "score"]}
        for fmt in FORMATS:
            commands[f"export-{fmt}"] = ["export", rec, "--to", fmt, "--out", d / f"export-{fmt}{_SUFFIX[fmt]}"]
        for cmd, argv in commands.items():
            name = f"{m.name}:{cmd}"
            jobs.append({"name": name, "argv": [str(a) for a in argv]})
            field = m.field
            if cmd == "export-dsec-flow" and field is None:
                field = "gt/flow"  # the base was simulated without geometry passes: refused, naming what is missing
            expect[name] = (field, dataset / REC_REL if cmd == "score" else rec)
    dataset = write_dataset(tmp_path / "base_dataset", base)
    for m in fuzz_cases.submission_mutations():
        sub = m.write(base_sub, tmp_path / f"{m.name}.h5")
        name = f"{m.name}:score"
        jobs.append({"name": name, "argv": ["score", str(sub), "--dataset", str(dataset),
                                            "--out", str(tmp_path / f"{m.name}-score")]})
        expect[name] = (m.field, sub)
    return jobs, expect


def test_commands_on_mutated_files_refuse_in_one_line_never_crash(base, tmp_path, child_env):
    jobs, expect = _jobs(base, tmp_path)
    (tmp_path / "jobs.json").write_text(json.dumps(jobs))
    proc = subprocess.run([sys.executable, "-m", "tests.hostile.fuzz_driver", str(tmp_path / "jobs.json"),
                           str(tmp_path / "out.json"), str(base)], capture_output=True, text=True, cwd=REPO,
                          env=child_env, timeout=600)
    last = proc.stdout.strip().splitlines()[-1:] or ["(none)"]
    assert proc.returncode == 0, f"driver ended with {proc.returncode} during {last[0]}\n{proc.stderr[-3000:]}"
    results = json.loads((tmp_path / "out.json").read_text())
    assert len(results) == len(jobs)
    tally: dict[str, int] = {}
    problems = []
    for r in results:
        field, path = expect[r["name"]]
        err = r["stderr"]
        lines = [line for line in err.splitlines() if line.startswith("simspad: error: ")]
        if "Traceback" in err or "internal error" in err or r["rc"] == "raised":
            problems.append(f"{r['name']}: crashed ({r['rc']}): {err[-1500:]}")
        elif field is None:
            if r["rc"] != 0:
                problems.append(f"{r['name']}: a valid file failed ({r['rc']}): {err[-1500:]}")
            tally["succeeded"] = tally.get("succeeded", 0) + 1
        elif r["rc"] != 2 or len(lines) != 1:
            problems.append(f"{r['name']}: rc {r['rc']}, expected 2 and one line: {err[-1500:]}")
        elif not re.search(re.escape(f"{path}: ") + _field_pattern(field), lines[0]):
            problems.append(f"{r['name']}: expected {path}: {field}: {lines[0]}")
        else:
            tally["refused"] = tally.get("refused", 0) + 1
    assert not problems, "\n".join(problems)
    kinds = {r["name"].split(":")[0] for r in results}
    print(f"fuzz stage 2: {len(kinds)} mutated files, {len(results)} commands: {tally}")


HEADLINES = {
    # issue 33: rc 139 / 134 with cf, "Can't decrement id ref count" with the other methods
    "x_65535": ("events/x", 5, 65535, ["evaluate", "{rec}", "--methods", "cf", "--out", "{tmp}/ev"],
                "/events/x: event 5: x outside the sensor"),
    # issue 33: MemoryError: Unable to allocate 1.00 TiB
    "t_2_62": ("events/t", -1, 1 << 62, ["export", "{rec}", "--to", "evt3", "--out", "{tmp}/x.raw"],
               "/events/t: event "),
    "polarity_7": ("events/p", 0, 7, ["export", "{rec}", "--to", "dsec", "--out", "{tmp}/x.h5"],
                   "/events/p: event 0: polarity"),
}


@pytest.mark.parametrize("case", sorted(HEADLINES))
def test_headline_findings_in_a_real_process(base, tmp_path, simspad_cli, case):
    name, index, value, argv, fragment = HEADLINES[case]
    rec = tmp_path / "rec.h5"
    rec.write_bytes(base.read_bytes())
    with h5py.File(rec, "r+") as f:
        data = f[name][()]
        data[index] = value
        del f[name]
        f.create_dataset(name, data=data.astype(np.dtype(data.dtype)))
    proc = simspad_cli.run(*[a.format(rec=rec, tmp=tmp_path) for a in argv])
    assert proc.returncode == 2 and proc.stderr.count("\n") == 1, (proc.returncode, proc.stderr)
    assert fragment in proc.stderr and str(rec) in proc.stderr, proc.stderr
    assert not [p for p in tmp_path.iterdir() if p.name not in ("rec.h5",)], "something was written"
