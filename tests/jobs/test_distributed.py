"""Capability studies on a Dask cluster give the in-process results (issue 8).

A light LocalCluster (threads, one worker, no dashboard) stands in for a real
cluster; the chunks travel through the scheduler exactly as they would to remote
workers (pickled job and data, results gathered in part order).
"""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import piecs_bayes.jobs as D
from piecs_bayes.errors import InputError
from piecs_bayes.io import load_study
from piecs_bayes.jobs import load_probe_data

distributed = pytest.importorskip("distributed")

BATCH = Path(__file__).resolve().parents[2] / "data" / "batch" / "study.toml"


@pytest.fixture(scope="module")
def study_probe():
    study = load_study(BATCH)
    files = sorted(study.path.parent.glob("part*.csv"))[:12]
    return study, load_probe_data(study, files)


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    ) as cl:
        yield cl


def _same(a, b):
    """The same results to the precision compiled code has: chunks of other sizes are
    other compiled shapes, whose last bits may differ (seen: 5e-20 mm in one u under
    --xla_cpu_max_isa=SSE4_2); 1e-12 relative is far below any printed digit."""
    assert a.parts == b.parts and a.notes == b.notes and list(a.features) == list(b.features)
    for fid, fa in a.features.items():
        fb = b.features[fid]
        np.testing.assert_allclose(fa.values, fb.values, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(fa.u, fb.u, rtol=1e-12, atol=1e-15)
        assert fa.summary() == fb.summary()


def test_capability_on_a_cluster_equals_in_process(study_probe, cluster):
    study, probe = study_probe
    local = D.capability_study(study, probe, n_draws=2000)
    seen = []
    with distributed.Client(cluster) as client:
        remote = D.capability_study(
            study,
            probe,
            n_draws=2000,
            scheduler=client,
            chunk_parts=5,
            progress=lambda i, n, p: seen.append((i, n)),
        )
    _same(local, remote)
    assert sorted(seen)[-1] == (12, 12) and len(seen) == 3
    # by address, as the CLI's --scheduler passes it
    by_address = D.capability_study(
        study, probe, n_draws=2000, scheduler=cluster.scheduler_address, chunk_parts=7
    )
    _same(local, by_address)


def test_joint_fits_stay_in_process(study_probe):
    study, probe = study_probe
    joint = replace(study, fit=replace(study.fit, free_transform=("z_offset",)))
    with pytest.raises(InputError, match="joint fits"):
        D.capability_study(joint, probe, scheduler="tcp://127.0.0.1:1")


def test_cli_capability_sends_chunks_to_the_scheduler(cluster, tmp_path, capsys):
    from piecs_bayes.cli import main

    out = tmp_path / "cap"
    argv = ["capability", str(BATCH), "--glob", "part0*.csv", "--out", str(out)]
    assert main([*argv, "--scheduler", cluster.scheduler_address, "--chunk-parts", "4"]) == 0
    text = capsys.readouterr().out
    assert "fitted 9/9 parts (part0" in text and f") on {cluster.scheduler_address}" in text
    remote = (out / "capability_parts.csv").read_text()
    assert main([*argv, "-q"]) == 0
    assert (out / "capability_parts.csv").read_text() == remote
