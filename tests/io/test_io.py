"""Study and probe-file validation: every bad input names file, line/key, column, feature, value."""

import math
import textwrap
from pathlib import Path

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.geometry import drawn_limits, drawn_scale
from piecs_bayes.io import load_study, read_probe_csv
from piecs_bayes.jobs import fit_study

STUDY = """\
[study]
name = "t"
units = "{units}"
probe_files = ["p.csv"]

[profile]
x_mode = "diameter"
{profile_extra}
[[profile.feature]]
id = "face"
type = "line"
start = [8.0, 0.0]
end = [24.0, 0.0]
tolerance_on = "length"

[[profile.feature]]
id = "dia"
type = "line"
start = [24.0, 0.0]
end = [{dia_end}, -30.0]
tolerance = [-0.01, 0.01]
tolerance_on = "diameter"

[probe]
ball_radius = 1.0
repeatability = 0.001
"""

DATA = Path(__file__).resolve().parents[2] / "data"


def write_study(tmp_path, *, units="mm", dia_end="24.0", profile_extra="", csv=None, extra=""):
    (tmp_path / "s.toml").write_text(
        STUDY.format(units=units, dia_end=dia_end, profile_extra=profile_extra) + extra
    )
    if csv is not None:
        (tmp_path / "p.csv").write_text(textwrap.dedent(csv))
    return tmp_path / "s.toml"


GOOD_CSV = """\
# a comment
feature,x,z
dia,26.02,-5
dia,26.02,-15
dia,26.02,-25
"""


def test_a_valid_study_and_probe_file(tmp_path):
    study = load_study(write_study(tmp_path, csv=GOOD_CSV))
    assert study.profile.ids == ("face", "dia")
    assert study.profile["dia"].p0 == (12.0, 0.0)  # diameter 24 -> radius 12
    probe = read_probe_csv(tmp_path / "p.csv", features=study.profile.ids)
    assert np.allclose(probe.points[:, 0], 13.01)  # X diameter in the file
    assert list(probe.lines) == [3, 4, 5]


def test_tolerances_are_read_as_drawn(tmp_path):
    """Ø24 ±0.010 as drawn limits the radius (the normal deviation) to ±0.005; a face's
    tolerance is on Z; a bore's diameter grows when material is taken away."""
    study = load_study(write_study(tmp_path))
    dia, face = study.profile["dia"], study.profile["face"]
    assert (dia.tolerance_on, dia.tolerance) == ("diameter", (-0.005, 0.005))
    assert drawn_limits(dia) == (-0.01, 0.01) and drawn_scale(dia) == 2.0
    assert (face.tolerance_on, face.tolerance) == ("length", (-0.01, 0.01))  # the default
    assert drawn_scale(face) == 1.0  # the end face: outward is +Z
    path = write_study(tmp_path, profile_extra='kind = "internal"\n')
    text = path.read_text().replace("tolerance = [-0.01, 0.01]", "tolerance = [-0.004, 0.012]")
    path.write_text(text.replace('tolerance_on = "diameter"', 'tolerance_on = "radius"'))
    bore = load_study(path).profile["dia"]
    # a bore: outward (out of the material) points to the axis; +material = smaller radius
    assert drawn_scale(bore) == -1.0 and bore.tolerance == pytest.approx((-0.012, 0.004))
    assert drawn_limits(bore) == pytest.approx((-0.004, 0.012))
    path.write_text(text)  # the same limits on the diameter
    assert load_study(path).profile["dia"].tolerance == pytest.approx((-0.006, 0.002))
    taper = write_study(tmp_path, dia_end="30.0")
    taper.write_text(
        taper.read_text().replace('tolerance_on = "diameter"', 'tolerance_on = "normal"')
    )
    t = load_study(taper).profile["dia"]
    assert (t.tolerance_on, t.tolerance, drawn_scale(t)) == ("normal", (-0.01, 0.01), 1.0)


def _refused_after_edit(tmp_path, old, new, pattern):
    """The demo-like study with `old` replaced by `new` is refused with `pattern`."""
    path = write_study(tmp_path)
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new, 1))
    with pytest.raises(InputError, match=pattern):
        load_study(path)


@pytest.mark.parametrize(
    "old, new, pattern",
    [
        (  # missing: the message names the feature and shows the line to add
            'tolerance_on = "diameter"\n',
            "",
            r"feature 'dia': profile\.feature\[1\]\.tolerance_on: missing: 'dia' is a diameter "
            r"\(cylinder\); say what its tolerance \[-0\.01, 0\.01\] limits: add the line "
            r'tolerance_on = "diameter" to its \[\[profile\.feature\]\] table \(the tolerance is '
            r'then on the diameter Ø, as drawn; "radius" for a tolerance on the radius\)',
        ),
        (
            'tolerance_on = "length"\n',
            "",
            r"feature 'face': profile\.feature\[0\]\.tolerance_on: missing: 'face' is a face or "
            r"shoulder; say what its tolerance \(default \[-0\.01, 0\.01\]\) limits: add the "
            r'line tolerance_on = "length"',
        ),
        (
            'tolerance_on = "diameter"',
            'tolerance_on = "normal"',
            r"profile\.feature\[1\]\.tolerance_on: 'normal' does not fit 'dia', a diameter "
            r'\(cylinder\): write tolerance_on = "diameter" or tolerance_on = "radius"',
        ),
        (
            'tolerance_on = "length"',
            'tolerance_on = "diameter"',
            r"'diameter' does not fit 'face', a face or shoulder: write tolerance_on = \"length\"",
        ),
        (
            'tolerance_on = "diameter"',
            'tolerance_on = "dia"',
            r"tolerance_on: unknown value 'dia'; expected one of 'diameter', 'radius', 'length', "
            r"'normal'",
        ),
        (
            'tolerance_on = "diameter"',
            'tolerance_on = "diameter"\ntolerance_in = "mm"',
            r"profile\.feature\[1\]\.tolerance_in: unknown key 'tolerance_in'; did you mean "
            r"'tolerance_on'\?",
        ),
    ],
)
def test_a_tolerance_must_say_what_it_limits(tmp_path, old, new, pattern):
    _refused_after_edit(tmp_path, old, new, pattern)


def test_shipped_studies_keep_their_tolerance_band():
    """The demo and batch studies say what their tolerances limit; the physical band
    (the normal deviation's limits) is the one they had before it was said."""
    band = {"face_end": 0.05, "dia_24": 0.01, "taper": 0.02, "dia_30": 0.01,
            "fillet": 0.05, "shoulder": 0.03, "dia_44": 0.015}  # fmt: skip
    on = {"face_end": "length", "dia_24": "diameter", "taper": "normal", "dia_30": "diameter",
          "fillet": "normal", "shoulder": "length", "dia_44": "diameter"}  # fmt: skip
    for name in ("demo", "batch"):
        study = load_study(DATA / name / "study.toml")
        for f in study.profile:
            assert f.tolerance == pytest.approx((-band[f.id], band[f.id])), (name, f.id)
            assert f.tolerance_on == on[f.id], (name, f.id)
    assert drawn_limits(study.profile["dia_24"]) == pytest.approx((-0.02, 0.02))


def test_inch_study_is_converted_to_mm(tmp_path):
    study = load_study(write_study(tmp_path, units="in"))
    assert study.profile["dia"].p0 == pytest.approx((12.0 * 25.4, 0.0))
    assert study.probe.ball_radius == pytest.approx(25.4)
    probe = (
        read_probe_csv(tmp_path / "p.csv", units="in") if (tmp_path / "p.csv").exists() else None
    )
    assert probe is None


@pytest.mark.parametrize(
    "csv, pattern",
    [
        ("feature,x\ndia,26\n", r"p\.csv:1, column 'z': missing required column 'z'"),
        ("feature,x,z\ndia,26.0,abc\n", r"p\.csv:2, column 'z': not a number: 'abc'"),
        ("feature,x,z\ndia,nan,-5\n", r"p\.csv:2, column 'x': value must be finite, got 'nan'"),
        (
            "feature,x,z\n# c\nbore,26,-5\n",
            r"p\.csv:3, column 'feature', feature 'bore': unknown feature id 'bore'; the study's profile has face, dia",
        ),
        ("feature,x,z\n", r"p\.csv: probe file has a header but no data rows"),
        ("feature,x,z\ndia,26\n", r"p\.csv:2: row has 2 cells, the header has 3"),
        (
            "feature,x,z,colour\ndia,26,-5,red\n",
            r"p\.csv:1, column 'colour': unknown column 'colour'",
        ),
        ("", r"p\.csv: probe file is empty"),
    ],
)
def test_bad_probe_files_are_named(tmp_path, csv, pattern):
    (tmp_path / "p.csv").write_text(csv)
    with pytest.raises(InputError, match=pattern):
        read_probe_csv(tmp_path / "p.csv", features=("face", "dia"))


def test_too_few_points_for_a_feature(tmp_path):
    study = load_study(write_study(tmp_path, csv="feature,x,z\ndia,26.02,-5\ndia,26.02,-15\n"))
    with pytest.raises(
        InputError, match=r"p\.csv, feature 'dia': 2 point\(s\) are too few for a line: at least 3"
    ):
        fit_study(study)


def test_unknown_unit(tmp_path):
    with pytest.raises(
        InputError,
        match=r"s\.toml: study\.units: unknown value 'furlong'; expected one of 'mm', 'in'",
    ):
        load_study(write_study(tmp_path, units="furlong"))


def test_non_connected_profile(tmp_path):
    path = write_study(tmp_path, dia_end="24.0")
    text = path.read_text().replace("start = [24.0, 0.0]", "start = [24.2, 0.0]")
    path.write_text(text)
    with pytest.raises(
        InputError,
        match=r"feature 'dia': profile is not connected: 'face' ends at \(x=12, z=0\) but 'dia' starts at \(x=12.1, z=0\)",
    ):
        load_study(path)


@pytest.mark.parametrize(
    "old, new, pattern",
    [
        (
            'type = "line"\nstart = [24.0',
            'type = "spline"\nstart = [24.0',
            r"profile\.feature\[1\]\.type, feature 'dia'|feature 'dia': profile\.feature\[1\]\.type: unknown feature type 'spline'",
        ),
        (
            "end = [24.0, -30.0]",
            'end = [24.0, "a"]',
            r"feature 'dia': profile\.feature\[1\]\.end: expected a point \[x, z\] of two numbers",
        ),
        ("ball_radius = 1.0", "ball_radius = -1.0", r"probe\.ball_radius: must be > 0, got -1\.0"),
        (
            "tolerance = [-0.01, 0.01]",
            "tolerance = [0.01, -0.01]",
            r"feature 'dia': profile\.feature\[1\]\.tolerance: expected \[lower, upper\]",
        ),
        (
            'probe_files = ["p.csv"]',
            'probe_files = ["missing*.csv"]',
            r"study\.probe_files: no file matches 'missing\*\.csv'",
        ),
    ],
)
def test_bad_study_values_are_named(tmp_path, old, new, pattern):
    _refused_after_edit(tmp_path, old, new, pattern)


def test_unknown_uncertainty_source_and_bad_toml(tmp_path):
    path = write_study(
        tmp_path, extra='\n[uncertainty]\nhumidity = { dist = "normal", sd = 1.0 }\n'
    )
    with pytest.raises(
        InputError, match=r"uncertainty\.humidity: unknown uncertainty source 'humidity'"
    ):
        load_study(path)
    (tmp_path / "bad.toml").write_text("[study\n")
    with pytest.raises(InputError, match=r"bad\.toml: not valid TOML"):
        load_study(tmp_path / "bad.toml")


def test_ball_too_big_for_a_concave_fillet(tmp_path):
    from piecs_bayes.geometry import MachineTransform
    from piecs_bayes.simulate import demo_profile, study_toml_text

    text = study_toml_text(
        demo_profile(),
        name="x",
        probe_files=[],
        program=None,
        ball_radius=3.5,
        ball_radius_u=0.0,
        repeatability=0.001,
        transform=MachineTransform(),
    )
    (tmp_path / "s.toml").write_text(text)
    with pytest.raises(
        InputError,
        match=r"feature 'fillet': concave arc radius 3 mm is not larger than the probe ball radius 3.5 mm",
    ):
        load_study(tmp_path / "s.toml")
    assert math.isfinite(1.0)


@pytest.mark.parametrize(
    "section, pattern",
    [
        (
            "[program]\nmapping = { bore = [70] }\n",
            r"program\.mapping\.bore, feature 'bore'|feature 'bore': program\.mapping\.bore: unknown feature id 'bore'",
        ),
        (
            "[program]\nmapping = { dia = [0] }\n",
            r"program\.mapping\.dia: expected program line numbers \(positive integers\), got \[0\]",
        ),
        ("[program]\nnose_radius = -0.4\n", r"program\.nose_radius: must be > 0, got -0\.4"),
        ('[program]\ntool_table = "none.tbl"\n', r"program\.tool_table: tool table not found"),
    ],
)
def test_bad_program_settings_are_named(tmp_path, section, pattern):
    with pytest.raises(InputError, match=pattern):
        load_study(write_study(tmp_path, extra="\n" + section))


def test_program_settings_are_read(tmp_path):
    study = load_study(
        write_study(
            tmp_path, extra="\n[program]\nnose_radius = 0.4\nmapping = { dia = [70, 80] }\n"
        )
    )
    assert study.program_settings.nose_radius == pytest.approx(0.4)
    assert dict(study.program_settings.mapping) == {"dia": (70, 80)}


def test_probe_rows_end_at_newlines_only(tmp_path):
    """A form feed or a Unicode line separator inside a comment is not a new row, and
    CRLF files read like LF files (line numbers are the file's)."""
    from piecs_bayes.io import read_probe_csv

    p = tmp_path / "p.csv"
    p.write_bytes(
        b"# exported\x0c page 2 \xe2\x80\xa8 note\r\nfeature,x,z\r\ndia,24.0,-5.0\r\n"
        b"dia,24.0,-6.0\r\ndia,24.0,-7.0\r\n"
    )
    d = read_probe_csv(p, x_mode="diameter")
    assert len(d) == 3 and list(d.lines) == [3, 4, 5]


# --------------------------------------------------------------------------- issue 29

UNIT_STUDY = """\
[study]
name = "t"
units = "{units}"

[profile]
x_mode = "diameter"

[[profile.feature]]
id = "dia"
type = "line"
start = [{d}, 0.0]
end = [{d}, {z}]
tolerance = [{t0}, {t1}]
tolerance_on = "diameter"

[probe]
ball_radius = {rb}
repeatability = {rep}

[machine]
x_centre = {xc}
z_offset = {zo}

[uncertainty]
repeatability = {{ dist = "lognormal", mu = {mu}, sigma = 0.3 }}
ball_radius = {{ dist = "normal", mean = 0.0, sd = {sd} }}
"""


def _unit_study(tmp_path, units: str) -> Path:
    """One study in mm or in inches, every length (the prior's too) the same in mm."""
    k = 1.0 if units == "mm" else 25.4
    lengths = dict(d=24.0, z=-30.0, t0=-0.01, t1=0.01, rb=1.0, rep=0.0015, xc=0.0021,
                   zo=-312.4873, sd=0.0005)  # fmt: skip
    path = tmp_path / f"{units}.toml"
    path.write_text(
        UNIT_STUDY.format(
            units=units,
            mu=repr(math.log(0.0015 / k)),
            **{n: repr(v / k) for n, v in lengths.items()},
        )
    )
    return path


def test_an_inch_lognormal_prior_is_the_mm_one(tmp_path):
    """mu is the log of a length: mu_mm = mu_in + ln(25.4) (sigma unchanged); the inch
    study's prior is the mm study's: same parameters, log-density and samples."""
    from piecs_bayes.fit.mcmc import prior_from_spec

    mm, inch = (load_study(_unit_study(tmp_path, u)) for u in ("mm", "in"))
    assert inch.transform.z_offset == pytest.approx(mm.transform.z_offset, rel=1e-14)
    assert inch.sources["ball_radius"]["sd"] == pytest.approx(0.0005, rel=1e-14)
    a, b = (prior_from_spec("repeatability", dict(s.sources["repeatability"])) for s in (mm, inch))
    assert (b.mu, b.sigma) == pytest.approx((a.mu, a.sigma), rel=1e-14, abs=1e-14)
    assert math.exp(b.mu) == pytest.approx(0.0015, rel=1e-13)  # the median, in mm
    x = np.linspace(2e-4, 5e-3, 25)
    np.testing.assert_allclose(np.asarray(b.log_pdf(x)), np.asarray(a.log_pdf(x)), rtol=1e-12)
    np.testing.assert_allclose(
        b.sample(np.random.default_rng(3), 100), a.sample(np.random.default_rng(3), 100), rtol=1e-12
    )


@pytest.mark.parametrize(
    "key, value, pattern",
    [
        ("z_offset", "1e300", r"machine\.z_offset: 1e\+300 mm is a work offset beyond any "
         r"machine's travel \(expected \|z_offset\| <= 100 m, 100000 mm\)"),
        ("x_centre", "-2e5", r"machine\.x_centre: -200000 mm is a centre-line offset beyond"),
        ("scale_x", "0.5", r"machine\.scale_x: 0\.5 is an X axis scale error above 1 %"),
        ("scale_z", "-1e300", r"machine\.scale_z: -1e\+300 is a Z axis scale error above 1 %"),
        ("rotation", "0.2", r"machine\.rotation: 0\.2 rad is a probe-frame rotation above"),
        ("rotation", "nan", r"machine\.rotation: expected a finite number, got nan"),
    ],
)  # fmt: skip
def test_absurd_machine_numbers_are_named_at_study_load(tmp_path, key, value, pattern):
    path = write_study(tmp_path, extra=f"\n[machine]\n{key} = {value}\n")
    with pytest.raises(InputError, match=r"s\.toml: " + pattern) as exc:
        load_study(path)
    assert exc.value.file == str(path)


def test_machine_limits_in_an_inch_study_and_the_shipped_studies_pass(tmp_path):
    with pytest.raises(
        InputError, match=r"machine\.z_offset: 4000 in is a work offset .*3937 in\)"
    ):
        load_study(write_study(tmp_path, units="in", extra="\n[machine]\nz_offset = 4000\n"))
    load_study(write_study(tmp_path, units="in", extra="\n[machine]\nz_offset = 3900\n"))
    for name in ("demo", "batch"):
        load_study(DATA / name / "study.toml")


@pytest.mark.parametrize(
    "old, new, pattern",
    [
        ("end = [24.0, -30.0]", "end = [24.0, -1e300]",
         r"feature 'dia': profile\.feature\[1\]\.end: z = -1e\+300 is beyond any plausible "
         r"part size \(expected \|z\| <= 100 m, 100000 mm\)"),
        ("start = [8.0, 0.0]", "start = [3e5, 0.0]",
         r"feature 'face': profile\.feature\[0\]\.start: x = 300000 \(a diameter\) is beyond"),
    ],
)  # fmt: skip
def test_a_feature_coordinate_beyond_any_part_is_named_at_study_load(tmp_path, old, new, pattern):
    _refused_after_edit(tmp_path, old, new, pattern)


def test_the_probe_files_of_a_run_are_a_tuple_and_a_comma_in_a_name_stays(tmp_path):
    """`ProbeData.file` of several files is the tuple of their paths (it was their names
    joined by commas, which a name with a comma split wrongly); messages show them."""
    from piecs_bayes.errors import shown_files
    from piecs_bayes.jobs import load_probe_data

    path = write_study(tmp_path, csv=GOOD_CSV)
    (tmp_path / "a,b.csv").write_text(GOOD_CSV.replace("26.02,-15", "26.03,-15"))
    study = load_study(path)
    files = (tmp_path / "a,b.csv", tmp_path / "p.csv")
    probe = load_probe_data(study, files)
    assert probe.file == tuple(map(str, files)) and probe.parts == ("a,b", "p")
    assert probe.file_text == f"{files[0]}, {files[1]}"
    one = read_probe_csv(tmp_path / "p.csv")
    assert one.file == (str(tmp_path / "p.csv"),) and one.for_part("p").file == one.file
    with pytest.raises(InputError, match="the probe data hold 2 parts") as exc:
        fit_study(study, probe)
    assert exc.value.file == probe.file
    assert str(exc.value).startswith(f"{files[0]}, {files[1]}: the probe data hold 2 parts")
    single = InputError("x", file=(str(files[0]),))
    assert single.file == str(files[0]) and str(single) == f"{files[0]}: x"
    many = [f"p{i:02d},x.csv" for i in range(5)]
    assert shown_files(many) == "p00,x.csv, ..., p04,x.csv (5 files)"
    assert shown_files("a,b,c,d,e.csv") == "a,b,c,d,e.csv"


def test_a_wrong_profile_kind_is_named_with_the_study_file_and_key(tmp_path):
    """Shaft data under `kind = "internal"`: the probe file is fine, the study's kind is
    not; the error names the study file and `profile.kind` first, then the worst point."""
    from piecs_bayes.jobs import load_probe_data

    path = write_study(tmp_path, profile_extra='kind = "internal"\n', csv=GOOD_CSV)
    with pytest.raises(InputError) as exc:
        load_probe_data(load_study(path))
    text = str(exc.value)
    assert exc.value.file == str(path) and exc.value.value == "internal", text
    assert text.startswith(
        f"{path}: profile.kind: 'internal' does not fit the probe data: the ball centres "
        "of part 'p' lie on the material side of an internal profile (3 of 3 points"
    ), text
    assert f"the worst at {tmp_path / 'p.csv'}:3, feature 'dia': x = 26.02 (a diameter)" in text
    assert text.endswith('for a shaft, write [profile] kind = "external"'), text


@pytest.mark.parametrize(
    "units, x_mode, cell, shown",
    [
        ("mm", "diameter", "1e300", "x = 1e+300 (a diameter), z = -15 in the file"),
        ("in", "radius", "-2.5e7", "x = -25000000 (a radius), z = -15 in the file"),
    ],
)
def test_an_implausible_point_quotes_x_as_the_file_writes_it(tmp_path, units, x_mode, cell, shown):
    """x = 1e300 among valid points: the message gave '+5e+299 mm from its nominal' (the
    halved diameter in mm); it quotes the file's value and says it is a diameter."""
    from piecs_bayes.jobs import load_probe_data

    csv = GOOD_CSV.replace("26.02,-15", f"{cell},-15")  # the worst point: line 4
    path = write_study(tmp_path, units=units, csv=csv)
    if x_mode == "radius":
        path.write_text(path.read_text().replace("[probe]\n", '[probe]\nx_mode = "radius"\n'))
    study = load_study(path)
    with pytest.raises(InputError, match="implausible probe point") as exc:
        load_probe_data(study)
    assert f"p.csv:4, feature 'dia': implausible probe point of part 'p': {shown}: " in str(
        exc.value
    ), str(exc.value)
