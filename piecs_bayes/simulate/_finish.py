r"""Simulated finished-part measurements of a simulated run (the post-process loop).

The shipped batch (`data/batch`) holds each part's true deviations (`truth.json`) at the
semifinish probing. [`write_finish`][] simulates the finish cut repeating a share of
them: for part $k$ and feature $f$, with $\delta_{kf}$ the true normal deviation at the
characteristic point (`at`, the nominal mid-point by default),
$\phi_{kf} = \beta_f\,\delta_{kf} + e_{kf}$, $e_{kf} \sim N(0, s_f^2)$, cut without any
feedback correction, and measured on a CMM, $m_{kf} = \phi_{kf} + N(0, u_\text{CMM}^2)$.
It writes one CSV per finished part (every `every`-th; docs/formats.md, "Finished-part
measurements"), each deviation as drawn with its u, and the truth ($\beta_f$, $s_f$,
$u_\text{CMM}$, the seed, every $\phi_{kf}$ and $\delta_{kf}$ as normal deviations in
mm) in `truth.json` beside them.

Why the finish cut repeats a share: docs/models/simulation.md.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from ..geometry import drawn_scale
from ..uncertainty import normal_deviation

#: the defaults of [`write_finish`][] (mm)
FINISH_DEFAULTS = {"transfer": 0.85, "finish_sd": 0.0003, "u_cmm": 0.0005, "every": 3}


def _char(feature, devs: Mapping[str, float], at: float) -> float:
    d = np.array([float(devs[name]) for name in feature.param_names])
    return float(normal_deviation(feature, d, at))


def write_finish(
    out_dir,
    truth_json,
    *,
    transfer: float | Mapping[str, float] = FINISH_DEFAULTS["transfer"],
    finish_sd: float = FINISH_DEFAULTS["finish_sd"],
    u_cmm: float = FINISH_DEFAULTS["u_cmm"],
    every: int = FINISH_DEFAULTS["every"],
    parts: Sequence[str] | None = None,
    study=None,
    at: float = 0.5,
    seed: int = 17,
) -> dict:
    """Simulate and write finished-part measurements of a simulated run.

    **Arguments:**

    - `out_dir`: the folder to write (`finish_<part>.csv` per part, `truth.json`).
    - `truth_json`: the run's truth (`data/batch/truth.json`, `jobs.simulate`).
    - `transfer`: $\\beta$ for every feature, or by feature id.
    - `finish_sd`: sd of the finish cut's own scatter $s_f$ (mm); `u_cmm`: the CMM's
      standard uncertainty (mm), written in the `u` column.
    - `every`: measure every `every`-th part (part `every`, `2 every`, ...), unless
      `parts` names them.
    - `study`: the run's study (`io.Study`, or its path; default `study.toml` beside
      `truth_json`): the profile, the drawn coordinates and the units (mm).
    - `at`: the characteristic point as a fraction of each feature (0.5: `"mid"`).
    - `seed`: the random seed.

    **Returns:** the truth written to `truth.json`.
    """
    from ..io import load_study, write_text_atomic

    truth_json = Path(truth_json)
    run = json.loads(truth_json.read_text(encoding="utf-8"))
    if study is None or isinstance(study, str | Path):
        study = load_study(study or truth_json.parent / "study.toml")
    profile = study.profile
    every = int(every)
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every!r}")
    names = [p["part"] for p in run["parts"]]
    chosen = list(parts) if parts is not None else names[every - 1 :: every]
    beta = {f: float(transfer[f] if isinstance(transfer, Mapping) else transfer)
            for f in profile.ids}  # fmt: skip
    rng = np.random.default_rng(seed)
    out = Path(out_dir)
    records = []
    by_part = {p["part"]: p for p in run["parts"]}
    for name in chosen:
        rec = by_part[name]
        lines = [
            f"# Simulated finished part {name} (CMM; seed {seed}; truth in truth.json).",
            "# deviation: at the feature's mid-point, as drawn (on tolerance_on), mm.",
            "part,feature,deviation,u",
        ]
        feats = {}
        for f in profile.features:
            if f.id not in rec["deviations"]:
                continue
            delta = _char(f, rec["deviations"][f.id], at)
            phi = beta[f.id] * delta + rng.normal(0.0, finish_sd)
            meas = phi + rng.normal(0.0, u_cmm)
            k = drawn_scale(f)
            lines.append(f"{name},{f.id},{k * meas:.6f},{abs(k) * u_cmm:.6f}")
            feats[f.id] = {"semifinish_mm": delta, "finish_mm": phi, "measured_mm": meas}
        write_text_atomic(out / f"finish_{name}.csv", "\n".join(lines) + "\n")
        records.append({"part": name, "features": feats})
    doc = {
        "description": "Simulated finished-part measurements of the batch run: finish "
        "deviation = transfer x semifinish deviation + finish scatter, measured with "
        "u_cmm; normal deviations (mm) at the characteristic point, cut without feedback.",
        "source": truth_json.name,
        "seed": seed,
        "at": at,
        "transfer": beta,
        "finish_sd_mm": finish_sd,
        "u_cmm_mm": u_cmm,
        "parts": records,
    }
    write_text_atomic(out / "truth.json", json.dumps(doc, indent=2) + "\n")
    return doc
