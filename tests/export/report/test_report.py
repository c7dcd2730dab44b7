"""The job report: run_job's bundle, the self-contained HTML, the PDF pages, the CLI.

One short (not converged, on purpose: fast) Bayesian run of the demo part is shared
by the module; the convergence warning it raises is expected and filtered.
"""

from __future__ import annotations

import base64
import dataclasses
import io
import re
import shutil
from html.parser import HTMLParser
from pathlib import Path
from types import MappingProxyType

import pytest
from pypdf import PdfReader
from scipy import stats

from piecs_bayes.cli import main
from piecs_bayes.export.report import report_files, report_html, summary_html, summary_rows
from piecs_bayes.export.report._sections import SECTIONS
from piecs_bayes.jobs import JobOptions, JobResults, run_job

DATA = Path(__file__).resolve().parents[3] / "data"
DEMO = DATA / "demo" / "study.toml"
BATCH = DATA / "batch" / "study.toml"
PNG = b"\x89PNG\r\n\x1a\n"

#: figures each section must embed for the demo part (Bayesian run, one part)
DEMO_FIGURES = {
    "verdict": 0,
    "summary": 0,
    "profile": 2,
    "residuals": 1,
    "posterior": 3,
    "budget": 1,
    "capability": 0,
    "program": 0,
    "errspec": 0,
    "inputs": 0,
}


class _Sections(HTMLParser):
    """Collects, per <section id>, its heading, text, <img> sources and external links."""

    def __init__(self):
        super().__init__()
        self.order: list[str] = []
        self.imgs: dict[str, list[str]] = {}
        self.text: dict[str, list[str]] = {}
        self.external: list[str] = []
        self.current = None

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "section":
            self.current = a["id"]
            self.order.append(self.current)
            self.imgs[self.current] = []
            self.text[self.current] = []
        if tag == "img" and self.current:
            self.imgs[self.current].append(a["src"])
        for key in ("src", "href"):
            v = a.get(key, "")
            if v and not (v.startswith("data:") or v.startswith("#")):
                self.external.append(v)
        if tag in ("link", "script"):
            self.external.append(tag)

    def handle_endtag(self, tag):
        if tag == "section":
            self.current = None

    def handle_data(self, data):
        if self.current:
            self.text[self.current].append(data)


def _parse(text: str) -> _Sections:
    p = _Sections()
    p.feed(text)
    return p


@pytest.fixture(scope="module")
def demo_results():
    import warnings

    from piecs_bayes.fit.mcmc import ConvergenceWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        return run_job(DEMO, JobOptions(nsteps=400, seed=1, nose_radius=0.4))


@pytest.fixture(scope="module")
def demo_report(demo_results):
    return report_files(demo_results)


def test_bundle_is_immutable_and_complete(demo_results):
    res = demo_results
    assert isinstance(res, JobResults)
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.fit = None  # type: ignore[misc]
    for name in ("gains", "unavailable", "versions", "settings", "timings"):
        assert isinstance(getattr(res, name), MappingProxyType), name
    assert res.bayes is not None and res.decisions is not None and res.program is not None
    assert res.uncertainty["monte_carlo"] is not None
    assert res.errspec is not None and res.offsets is not None
    assert set(res.unavailable) == {"capability"}  # one part only
    assert "1 part" in res.unavailable["capability"]
    # the decisions' gains drive the path: zero unless the verdict is "compensate"
    for d in res.decisions.decisions:
        assert (res.gains[d.feature] > 0.0) == (d.verdict == "compensate"), d.feature
    assert res.gains["dia_24"] == 1.0
    assert 0.0 <= min(res.gains.values()) and max(res.gains.values()) <= 1.0
    roles = [f.role for f in res.inputs]
    assert roles == ["study", "probe", "program"]
    assert all(len(f.sha256) == 64 for f in res.inputs)
    assert res.versions["piecs_bayes"] and res.versions["python"]
    rows = summary_rows(res)
    assert [r["feature"] for r in rows] == list(res.study.profile.ids)
    for r in rows:  # U = t(nu_eff) u at 95.45 % (k = 2 under the normal), Bayes beside
        k = stats.t.ppf(0.5 + 0.9544997361036416 / 2, r["dof"])
        assert 2.0 < k < 2.2 and r["U_um"] == pytest.approx(k * r["u_um"], rel=1e-9)
        assert abs(r["bayes_um"] - r["deviation_um"]) < 2 * r["U_um"]
    assert "face_end" in repr(res) and "<table>" in summary_html(res)


def test_html_is_self_contained_with_every_section_and_figure(demo_report, demo_results):
    text, _ = demo_report
    p = _parse(text)
    assert p.order == [sid for sid, _ in SECTIONS]
    assert p.external == []
    for sid, n in DEMO_FIGURES.items():
        assert len(p.imgs[sid]) == n, sid
        for src in p.imgs[sid]:
            assert src.startswith("data:image/png;base64,")
            assert base64.b64decode(src.split(",", 1)[1])[:8] == PNG
    body = {sid: " ".join(t) for sid, t in p.text.items()}
    assert "deviation ± U (µm)" in body["summary"] and "null band ± (µm)" in body["summary"]
    assert "applied gain" in body["summary"]
    for d in demo_results.decisions.decisions:
        assert d.verdict in body["summary"] and d.feature in body["verdict"]
        assert d.reasons[-1] in body["summary"]
    for want in ("conformance as measured", "verdict for the next part", "Ø ±20", "Z ±50",
                 "normal ±20", "What to load:", "Checked by:"):  # fmt: skip
        assert want in body["verdict"], want
    assert '<td class="does-not-conform">does not conform</td>' in text  # pass/fail colour
    assert "NOT converged" in body["summary"]  # 400 steps: said, not hidden
    assert "R-hat" in body["posterior"] and "ESS" in body["posterior"]
    assert "repeatability (%)" in body["budget"]
    assert "No capability study" in body["capability"]
    assert "N70 G1 X24.000 Z-30.000" in body["program"]  # the diff's removed line
    assert "x_radius" in body["errspec"] and "Tool-offset" in body["errspec"]
    for f in demo_results.inputs:
        assert f.sha256 in body["inputs"]
    assert "piecs-bayes report" in body["inputs"]


#: the pages the demo report fills (A4 landscape, text and figures flowed)
MAX_PAGES = 13


def test_pdf_text_is_in_the_standard_fonts_where_they_show_it(demo_report):
    """Lines the PDF's standard fonts can show (WinAnsi: µ, Ø, ±, °) are written in
    Helvetica and Courier, not embedded, one string per line; the few others (τ, Δ, σ)
    in the embedded DejaVu; the text extracts as written either way."""
    from matplotlib import rcParams

    from piecs_bayes.export.report._pdf_flow import _cp1252

    _, pdf = demo_report
    reader = PdfReader(io.BytesIO(pdf))
    fonts = {}
    for page in reader.pages:
        for font in page["/Resources"]["/Font"].values():
            font = font.get_object()
            fonts[str(font["/BaseFont"]).split("+")[-1]] = "/FontDescriptor" in font
    assert {"/Helvetica", "/Helvetica-Bold", "/Helvetica-Oblique"} <= set(fonts)
    assert not any(fonts[f] for f in ("/Helvetica", "/Helvetica-Bold", "/Helvetica-Oblique"))
    assert "DejaVuSans" in fonts and fonts["DejaVuSans"]  # embedded, for τ and the like
    text = "\n".join(page.extract_text() for page in reader.pages)
    for shown in ("Ø ±20", "µm", "τ: autocorrelation time"):
        assert shown in text, shown
    assert _cp1252("Ø24.000 ± 6.8 µm, 30°") and not _cp1252("τ") and not _cp1252("σ = 1.5")
    assert rcParams["pdf.use14corefonts"] is False  # set per line while drawing, restored


def test_pdf_has_the_expected_pages(demo_report, demo_results):
    _, pdf = demo_report
    assert pdf[:5] == b"%PDF-"
    reader = PdfReader(io.BytesIO(pdf))
    texts = [page.extract_text() for page in reader.pages]
    n = len(texts)
    assert n <= MAX_PAGES  # 18 before the flowed layout, five of them nearly empty
    for i, t in enumerate(texts, start=1):
        assert "piecs_bayes report ·" in t and f"page {i} of {n}" in t
    # the first page is the verdict: one row per feature as drawn, what to load, signature
    first = texts[0]
    assert "1. Verdict" in first and "2. Decisions per feature" not in first
    for d in demo_results.decisions.decisions:
        assert d.feature in first
    for text in ("conformance\nas measured", "Ø ±20", "Z ±50", "The part does NOT conform",
                 "What to load:", "Checked by:"):  # fmt: skip
        assert text in first, text
    assert re.search(
        r"dia_24 Ø24\.000, Z0\.000 to -30\.000 Ø ±20 \+\d+\.\d ± \d\.\d does not", first
    )
    # every section heads a page region, in order; every figure has its numbered caption
    starts = []
    for k, (_, title) in enumerate(SECTIONS, start=1):
        pages = [i for i, t in enumerate(texts) if f"{k}. {title}" in t]
        assert pages, title
        starts.append(pages[0])
    assert starts == sorted(starts)
    joined = "\n".join(texts)
    for k in range(1, sum(DEMO_FIGURES.values()) + 1):
        assert f"Figure {k} (section " in joined, k
    for label in ("τ: autocorrelation time", "ESS: effective sample size", "null band"):
        assert label in joined, label
    assert " um " not in joined and " um)" not in joined  # µm throughout


def test_sections_say_why_a_step_is_unavailable(tmp_path):
    """No Bayesian fit, and a program with a block off the profile: the job goes
    on, and the report says why each section is empty."""
    for name in ("study.toml", "probe_part01.csv"):
        shutil.copy(DATA / "demo" / name, tmp_path / name)
    prog = (DATA / "demo" / "finish.ngc").read_text()
    prog = prog.replace(
        "N90 G1 X30.000 Z-57.000\n", "N85 G1 X31.000 Z-50.000\nN90 G1 X30.000 Z-57.000\n"
    )
    (tmp_path / "finish.ngc").write_text(prog)
    res = run_job(tmp_path / "study.toml", JobOptions(bayes=False, errspec=False), progress=False)
    assert res.bayes is None and "bayes" in res.skipped
    assert "lies on no profile feature" in res.unavailable["program"]
    assert res.errspec is None and "errspec" in res.skipped
    assert res.path is not None and res.uncertainty["monte_carlo"] is None
    p = _parse(report_html(res))
    body = {sid: " ".join(t) for sid, t in p.text.items()}
    assert "No Bayesian fit" in body["posterior"] and p.imgs["posterior"] == []
    assert "lies on no profile feature" in body["program"]
    assert "No error specification" in body["errspec"]
    assert len(p.imgs["profile"]) == 2 and len(p.imgs["budget"]) == 1


def test_a_diameter_tolerance_is_reported_as_drawn(tmp_path):
    """Ø24 ±0.010 as drawn: the report shows ±10 µm on Ø (the decision works on the
    radius, ±5 µm), in the verdict, the decision table and the summary rows."""
    text = DEMO.read_text()
    head, rest = text.split('id = "dia_24"', 1)
    rest = rest.replace("tolerance = [-0.0200, 0.0200]", "tolerance = [-0.0100, 0.0100]", 1)
    (tmp_path / "study.toml").write_text(head + 'id = "dia_24"' + rest)
    shutil.copy(DATA / "demo" / "probe_part01.csv", tmp_path / "probe_part01.csv")
    shutil.copy(DATA / "demo" / "finish.ngc", tmp_path / "finish.ngc")
    res = run_job(
        tmp_path / "study.toml",
        JobOptions(bayes=False, uncertainty=False, program=False, errspec=False),
        progress=False,
    )  # fmt: skip
    d = res.decisions["dia_24"]
    assert d.tolerance == (-0.005, 0.005) and d.drawn_tolerance == (-0.01, 0.01)
    row = {r["feature"]: r for r in summary_rows(res)}["dia_24"]
    assert (row["coordinate"], row["tol_lower_um"], row["tol_upper_um"]) == ("diameter", -10, 10)
    assert row["deviation_um"] == pytest.approx(2e3 * d.estimate)
    p = _parse(report_html(res))
    for sid in ("verdict", "summary"):
        cells = " ".join(p.text[sid])
        assert "Ø ±10" in cells and "Ø ±20" in cells, sid  # dia_24 and dia_30


def test_capability_section_with_several_parts():
    files = sorted((DATA / "batch").glob("part*.csv"))[:8]
    res = run_job(
        BATCH,
        JobOptions(bayes=False, program=False),
        capability_files=files,
        progress=False,
    )
    assert res.capability is not None and len(res.capability.parts) == 8
    assert [f.role for f in res.inputs].count("probe (capability)") == 8
    p = _parse(report_html(res))
    body = " ".join(p.text["capability"])
    assert len(p.imgs["capability"]) == 2
    assert "Cpk" in body and "part01" in body
    assert "Q_MP" in body and "consumer's risk" in body and "verdict" in body
    assert res.capability["dia_24"].verdict in body


def test_progress_lines_go_to_a_callable():
    lines: list[str] = []
    run_job(
        DEMO,
        JobOptions(
            bayes=False,
            uncertainty=False,
            program=False,
            errspec=False,
            decisions=False,
            capability=False,
        ),
        progress=lines.append,
    )
    assert lines[0].startswith("read ") and lines[-1].startswith("main job finished in ")
    assert any(line.startswith("fitted 7 features") for line in lines)


def test_cli_report_writes_both_files_and_exit_codes(tmp_path, capsys):
    out = tmp_path / "rep"
    assert main(["report", str(DEMO), "--out", str(out), "--no-bayes", "--quiet"]) == 0
    assert (out / "report.html").read_text(encoding="utf-8").startswith("<!DOCTYPE html>")
    assert (out / "report.pdf").read_bytes()[:5] == b"%PDF-"
    assert capsys.readouterr().out == ""  # --quiet
    # bad input: exit 2 with the file named
    assert main(["report", str(tmp_path / "missing.toml"), "--out", str(out), "-q"]) == 2
    assert "missing.toml" in capsys.readouterr().err
    assert main(["report", str(DEMO), "--out", str(out), "--steps", "5", "-q"]) == 2
    assert "--steps" in capsys.readouterr().err


def test_every_command_has_help_with_an_example(capsys):
    commands = [
        ["fit"],
        ["compensate"],
        ["simulate"],
        ["demo"],
        ["report"],
        ["decide"],
        ["capability"],
        ["gcode"],
        ["gcode", "nose-comp"],
        ["gcode", "check"],
    ]
    for cmd in commands:
        with pytest.raises(SystemExit) as exc:
            main([*cmd, "--help"])
        assert exc.value.code == 0
        text = capsys.readouterr().out
        assert "example" in text, cmd
        assert "piecs-bayes " + cmd[0] in text.split("example", 1)[1], cmd
    for cmd in ("fit", "compensate", "demo", "report", "decide", "capability", "simulate"):
        with pytest.raises(SystemExit):
            main([cmd, "--help"])
        text = capsys.readouterr().out
        for opt in ("--out", "--seed", "--quiet"):
            assert opt in text, (cmd, opt)


def test_study_sets_the_sampler(tmp_path):
    """`[fit] bayes_steps` and friends are read from the study file (the demo's run
    length keeps it converged), and a bad value is refused with its key."""
    import tomllib

    from piecs_bayes.errors import InputError
    from piecs_bayes.io import load_study

    raw = tomllib.loads(DEMO.read_text())["fit"]
    fit = load_study(DEMO).fit
    assert fit.bayes_steps == raw["bayes_steps"] != 6000  # not the default
    text = DEMO.read_text().replace("[fit]\n", '[fit]\nlikelihood = "student_t"\nnu = 5\n')
    text = text.replace('probe_files = ["probe_part01.csv"]', "probe_files = []")
    text = text.replace('part_program = "finish.ngc"\n', "")
    (tmp_path / "s.toml").write_text(text)
    fit = load_study(tmp_path / "s.toml").fit
    assert (fit.likelihood, fit.nu) == ("student_t", 5.0)
    (tmp_path / "bad.toml").write_text(
        text.replace(f"bayes_steps = {raw['bayes_steps']}", 'bayes_steps = "many"')
    )
    with pytest.raises(InputError, match="fit.bayes_steps"):
        load_study(tmp_path / "bad.toml")
