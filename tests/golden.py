"""Golden outputs: the main job (``make demo``) and ``capability`` on data/batch.

Recorded once from a known-good commit and compared after every move of code (the
architecture refactor must not change a number). Record again, on purpose, with

    .venv/bin/python tests/golden.py --record

What is compared:

- every text output (CSV, JSON, G-code, diff, LinuxCNC tables, INI): byte for byte,
  but for time stamps (the adjusted program names the run's date); where they differ,
  the test reports the first differing number so that a reordered sum (last bits) is
  told apart from a real change;
- ``posterior.nc``: the SHA-256 of every posterior variable's float64 values and the
  stored attributes that are not timings (the netCDF file itself carries a creation
  time);
- ``report.html`` and the text of ``report.pdf``: SHA-256 after masking the only parts
  that legitimately change from run to run (the time stamp, wall times, samples per
  second).

The digests are only meaningful with the package versions they were recorded with
(JAX and NumPy change the last bits of reductions between releases, and one last bit
changes an MCMC chain's whole trajectory). ``constraints.txt`` pins those versions for
``make``; with other versions the test skips and says which differ.
"""

from __future__ import annotations

import hashlib
import json
import re
import sys
from importlib.metadata import version
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "tests" / "data" / "golden"
DEMO_STUDY = ROOT / "data" / "demo" / "study.toml"
BATCH_STUDY = ROOT / "data" / "batch" / "study.toml"
PACKAGES = ("jax", "jaxlib", "numpy", "scipy", "emcee", "optimistix", "equinox", "arviz")
BINARY = {"posterior.nc", "report.html", "report.pdf"}

_MASKS = (
    (re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(?:\.\d+)?(?:[+-]\d\d:\d\d|Z)?"), "<time>"),
    (re.compile(r"<caption>Wall time per step</caption>.*?</table>", re.S), "<walltimes>"),
    (re.compile(r"\d+(?:\.\d+)? ?s( sampling|,|\))"), r"<s>\1"),
    (re.compile(r"\d+(?:\.\d+)? effective samples"), "<n> effective samples"),
    # the PDF's fixed-width table: its column widths follow the widest wall time
    (re.compile(r"Wall time per step\n.*?(?=\npiecs_bayes report|\n\n|\Z)", re.S), "<walltimes>"),
    # ... and where the PDF draws it as a table: a step name and its seconds per line
    (
        re.compile(
            r"^(read|fit|bayes|decisions|path|uncertainty|program|errspec|capability)"
            r"\s+\d+\.\d+\s*$",
            re.M,
        ),
        r"\1 <s>",
    ),
)


#: the PDF's page footer ("piecs_bayes report · <study> · part <id> · <time> page 3 of 13")
_FOOTER = re.compile(r"^piecs_bayes report · .*page \d+ of \d+\s*$", re.M)


def _run(argv: list[str], shown: str) -> None:
    """Run the CLI in this process as ``piecs-bayes ARGV``. The report records the
    command line: it is given as ``shown`` (the command a user types, e.g. `make
    demo`'s), not pytest's nor the temporary output folder, whose length would
    change how the PDF wraps the line."""
    import os

    from piecs_bayes.cli import main

    saved, cwd = sys.argv, os.getcwd()
    sys.argv = shown.split()
    os.chdir(ROOT)  # paths as `make demo` gives them, relative to the repository
    try:
        rc = main(argv)
    finally:
        sys.argv = saved
        os.chdir(cwd)
    assert rc == 0, f"piecs-bayes {' '.join(argv)} exited {rc}"


def run_demo(out: Path) -> Path:
    """Exactly ``make demo`` (same study, same default seed), into ``out``."""
    study = str(DEMO_STUDY.relative_to(ROOT))
    _run(
        ["demo", study, "--out", str(out), "--quiet"],
        f"piecs-bayes demo {study} --out reports/demo",
    )
    return out


def run_capability(out: Path) -> Path:
    study = str(BATCH_STUDY.relative_to(ROOT))
    _run(["capability", study, "--out", str(out), "--quiet"], f"piecs-bayes capability {study}")
    return out


def masked(text: str) -> str:
    for pattern, repl in _MASKS:
        text = pattern.sub(repl, text)
    return text


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _posterior_digest(path: Path) -> dict:
    import numpy as np
    import xarray as xr

    with xr.open_dataset(path, group="posterior", engine="h5netcdf") as ds:
        out = {}
        for name in sorted(ds.data_vars):
            values = np.ascontiguousarray(ds[name].values, dtype=np.float64)
            out[name] = {"shape": list(values.shape), "sha256": _sha(values.tobytes())}
    return out


def _pdf_text(path: Path) -> str:
    from pypdf import PdfReader

    return "\n\f".join(page.extract_text() or "" for page in PdfReader(path).pages)


def digests(folder: Path) -> dict:
    """What is compared of the files that are not plain text."""
    out = {}
    if (folder / "posterior.nc").exists():
        out["posterior.nc"] = _posterior_digest(folder / "posterior.nc")
    if (folder / "report.html").exists():
        html = (folder / "report.html").read_text(encoding="utf-8")
        out["report.html"] = _sha(masked(html).encode())
    if (folder / "report.pdf").exists():
        # whitespace collapsed: how the PDF wraps a line and pads a column follows the
        # widths of the masked numbers (a 100 s step widens the wall-time table)
        # and without the page footers: where a page breaks follows those widths too
        # (a paragraph one line longer moves a table to the next page), not the content
        text = _FOOTER.sub("", masked(_pdf_text(folder / "report.pdf")))
        # masked again once the lines are joined: a slow run's wider numbers move a
        # line break between a number and its unit ("102.4 s\nsampling"), where the
        # line-wise masks miss it
        text = masked(" ".join(text.split()))
        out["report.pdf (text)"] = _sha(text.encode())
    return out


def versions() -> dict:
    return {p: version(p) for p in PACKAGES}


_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def first_difference(expected: str, actual: str) -> str:
    """Where two texts first differ, and by how much if it is a number."""
    for i, (a, b) in enumerate(zip(expected.splitlines(), actual.splitlines(), strict=False)):
        if a == b:
            continue
        na, nb = _NUMBER.findall(a), _NUMBER.findall(b)
        rel = ""
        if len(na) == len(nb):
            worst = max(
                (
                    abs(float(x) - float(y)) / max(abs(float(x)), 1e-300)
                    for x, y in zip(na, nb, strict=True)
                ),
                default=0.0,
            )
            rel = f" (largest relative difference of a number on the line: {worst:.1e})"
        return f"line {i + 1}: expected {a!r}, got {b!r}{rel}"
    return f"line counts differ: {len(expected.splitlines())} vs {len(actual.splitlines())}"


def compare(name: str, actual: Path) -> list[str]:
    """Every difference between the recorded outputs of ``name`` and folder ``actual``."""
    expected = GOLDEN / name
    manifest = json.loads((expected / "manifest.json").read_text())
    problems = []
    for fname in manifest["files"]:
        got = actual / fname
        if not got.exists():
            problems.append(f"{fname}: not written")
            continue
        want = (expected / fname).read_bytes()
        if got.read_bytes() == want:
            continue
        # the adjusted program and its diff carry the run's date in a comment
        want_text, got_text = masked(want.decode()), masked(got.read_text(encoding="utf-8"))
        if want_text != got_text:
            problems.append(f"{fname}: {first_difference(want_text, got_text)}")
    extra = sorted(
        p.name for p in actual.iterdir() if p.name not in manifest["files"] and p.name not in BINARY
    )
    if extra:
        problems.append(f"files not in the golden set: {extra}")
    now = digests(actual)
    for key, want in manifest["digests"].items():
        if now.get(key) != want:
            problems.append(f"{key}: digest differs")
    return problems


def record(name: str, folder: Path) -> None:
    dest = GOLDEN / name
    dest.mkdir(parents=True, exist_ok=True)
    for old in dest.iterdir():
        old.unlink()
    files = sorted(p.name for p in folder.iterdir() if p.name not in BINARY)
    for fname in files:
        (dest / fname).write_bytes((folder / fname).read_bytes())
    manifest = {"versions": versions(), "files": files, "digests": digests(folder)}
    (dest / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")


def version_mismatch(name: str) -> str | None:
    manifest = json.loads((GOLDEN / name / "manifest.json").read_text())
    now = versions()
    diff = {p: (v, now.get(p)) for p, v in manifest["versions"].items() if now.get(p) != v}
    if diff:
        return ", ".join(f"{p} {a} recorded, {b} installed" for p, (a, b) in diff.items())
    return None


if __name__ == "__main__" and "--record" in sys.argv:
    import os
    import tempfile

    os.environ.setdefault("MPLBACKEND", "Agg")
    os.environ.setdefault("JAX_PLATFORMS", "cpu")
    with tempfile.TemporaryDirectory() as tmp:
        record("demo", run_demo(Path(tmp) / "demo"))
        record("capability", run_capability(Path(tmp) / "capability"))
    print(f"recorded golden outputs under {GOLDEN}")
