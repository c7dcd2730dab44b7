"""Machine files: error-spec files, LinuxCNC compensation tables, tool-offset updates,
the one route of a correction to the machine, and the probe plan's files."""

from ... import _config  # noqa: F401  (float64 before any JAX array)
from ._errspec import errspec_texts as errspec_texts
from ._errspec import read_errspec as read_errspec
from ._errspec import write_errspec as write_errspec
from ._files import ALTERNATIVE as ALTERNATIVE
from ._files import CompensationOutputs as CompensationOutputs
from ._files import write_compensation_outputs as write_compensation_outputs
from ._linuxcnc import LinuxCNCComp as LinuxCNCComp
from ._linuxcnc import linuxcnc_comp_text as linuxcnc_comp_text
from ._linuxcnc import parse_linuxcnc_comp as parse_linuxcnc_comp
from ._linuxcnc import read_linuxcnc_comp as read_linuxcnc_comp
from ._linuxcnc import validate_linuxcnc_comp as validate_linuxcnc_comp
from ._linuxcnc import write_linuxcnc_comp as write_linuxcnc_comp
from ._offsets import g10_fanuc as g10_fanuc
from ._offsets import g10_linuxcnc as g10_linuxcnc
from ._offsets import offsets_from_json as offsets_from_json
from ._offsets import offsets_to_json as offsets_to_json
from ._plan import GAUGING_NAMES as GAUGING_NAMES
from ._plan import plan_figure as plan_figure
from ._plan import plan_json as plan_json
from ._plan import plan_program as plan_program
from ._plan import write_plan as write_plan
from ._routes import ROUTE_TITLES as ROUTE_TITLES
from ._routes import MachineFiles as MachineFiles
from ._routes import route_file_names as route_file_names
from ._routes import write_machine_files as write_machine_files
