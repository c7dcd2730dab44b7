"""Read and validate what the user brings: study files, probe CSVs, part programs."""

from ._probe import ProbeData as ProbeData
from ._probe import read_probe_csv as read_probe_csv
from ._study import CompensationSettings as CompensationSettings
from ._study import FitSettings as FitSettings
from ._study import ProbeSpec as ProbeSpec
from ._study import Study as Study
from ._study import load_study as load_study
