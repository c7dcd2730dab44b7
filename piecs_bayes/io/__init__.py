"""Read and validate what the user brings (study files, probe CSVs; programs: `gcode`),
read back a fit folder for `plan --more` (`read_more_points`), write a new study's text
(`study_toml`), and write files atomically, never over an input."""

from .. import _config  # noqa: F401  (float64 before any JAX array)
from ._atomic import write_bytes_atomic as write_bytes_atomic
from ._atomic import write_file_atomic as write_file_atomic
from ._atomic import write_text_atomic as write_text_atomic
from ._cal_file import ARTEFACT_KINDS as ARTEFACT_KINDS
from ._cal_file import CalibrationArtefact as CalibrationArtefact
from ._cal_file import CalibrationFile as CalibrationFile
from ._cal_file import CalibrationProbeFile as CalibrationProbeFile
from ._cal_file import parse_orders as parse_orders
from ._cal_file import read_calibration_file as read_calibration_file
from ._control_probe import PROBE_FORMATS as PROBE_FORMATS
from ._control_probe import PlanPoints as PlanPoints
from ._control_probe import read_control_probe as read_control_probe
from ._control_probe import read_plan_points as read_plan_points
from ._feedback_section import FEEDBACK_KEYS as FEEDBACK_KEYS
from ._feedback_section import FEEDBACK_POLICIES as FEEDBACK_POLICIES
from ._finish import FINISH_COLUMNS as FINISH_COLUMNS
from ._finish import FinishData as FinishData
from ._finish import read_finish_csv as read_finish_csv
from ._finish import read_finish_files as read_finish_files
from ._fit_folder import read_more_points as read_more_points
from ._frames import rows_to_dataframe as rows_to_dataframe
from ._plausibility import PlausibilityWarning as PlausibilityWarning
from ._plausibility import check_probe_data as check_probe_data
from ._probe import ProbeData as ProbeData
from ._probe import read_probe_csv as read_probe_csv
from ._probe import read_probe_csv_by_rows as read_probe_csv_by_rows
from ._probe_cal import CALIBRATION_FORMAT as CALIBRATION_FORMAT
from ._probe_cal import PER_AXIS as PER_AXIS
from ._probe_cal import ProbeCalibration as ProbeCalibration
from ._probe_cal import approach_angle as approach_angle
from ._probe_cal import coefficient_names as coefficient_names
from ._probe_cal import lobe_basis as lobe_basis
from ._probe_cal import read_probe_calibration as read_probe_calibration
from ._settings import APPLY_ROUTES as APPLY_ROUTES
from ._settings import PROGRAM_DIALECTS as PROGRAM_DIALECTS
from ._settings import CompensationSettings as CompensationSettings
from ._settings import FitSettings as FitSettings
from ._settings import ProbeSpec as ProbeSpec
from ._settings import ProgramSettings as ProgramSettings
from ._settings import Study as Study
from ._settings import parse_fix as parse_fix
from ._settings import split_fix as split_fix
from ._study import load_study as load_study
from ._study_text import FeatureText as FeatureText
from ._study_text import Setting as Setting
from ._study_text import StudyText as StudyText
from ._study_text import study_toml as study_toml
from ._study_text import toml_number as toml_number
from ._text import read_bytes as read_bytes
