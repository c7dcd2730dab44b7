"""PIECS mirroring and the machine-correction data: the adjusted tool path,
error-spec tables and tool-offset updates."""

from .. import _config  # noqa: F401  (float64 before any JAX array)
from ._errspec_tables import ERRSPEC_FORMAT_VERSION as ERRSPEC_FORMAT_VERSION
from ._errspec_tables import CompensationTable as CompensationTable
from ._errspec_tables import ErrorSpec as ErrorSpec
from ._mirror import AdjustedPath as AdjustedPath
from ._mirror import adjusted_geometry as adjusted_geometry
from ._mirror import adjusted_path as adjusted_path
from ._mirror import compensated_deviations as compensated_deviations
from ._tool_offsets import AxisCorrection as AxisCorrection
from ._tool_offsets import OffsetSettings as OffsetSettings
from ._tool_offsets import ToolOffsets as ToolOffsets
from ._tool_offsets import ToolOffsetUpdate as ToolOffsetUpdate
from ._tool_offsets import WearOffset as WearOffset
from ._tool_offsets import tool_offset_update as tool_offset_update
