"""Known-truth data: simulated parts and runs, the shipped data sets, a simulated
machine that runs gauging programs and probe calibrations."""

from .. import _config  # noqa: F401  (float64 before any JAX array)
from ._calibration import simulate_calibration as simulate_calibration
from ._calibration import write_calibration_sim as write_calibration_sim
from ._finish import FINISH_DEFAULTS as FINISH_DEFAULTS
from ._finish import write_finish as write_finish
from ._gauge import GaugeRun as GaugeRun
from ._gauge import GaugeTrip as GaugeTrip
from ._gauge import read_truth as read_truth
from ._gauge import simulate_gauge as simulate_gauge
from ._parts import BATCH_WEAR_PER_PART as BATCH_WEAR_PER_PART
from ._parts import DEMO_ERRORS as DEMO_ERRORS
from ._parts import DEMO_EXTRA as DEMO_EXTRA
from ._parts import DEMO_FEATURES as DEMO_FEATURES
from ._parts import DEMO_POINTS as DEMO_POINTS
from ._parts import DEMO_TRANSFORM as DEMO_TRANSFORM
from ._parts import ProcessErrors as ProcessErrors
from ._parts import SimulatedProbing as SimulatedProbing
from ._parts import batch_part_errors as batch_part_errors
from ._parts import demo_profile as demo_profile
from ._parts import probe_csv_text as probe_csv_text
from ._parts import process_deviations as process_deviations
from ._parts import simulate_parts as simulate_parts
from ._parts import simulate_probe as simulate_probe
from ._parts import study_toml_text as study_toml_text
from ._parts import write_batch as write_batch
from ._parts import write_demo as write_demo
