"""From fitted deviations to decisions: PIECS mirroring, capability, decision rules."""

from ._mirror import AdjustedPath as AdjustedPath
from ._mirror import adjusted_geometry as adjusted_geometry
from ._mirror import adjusted_path as adjusted_path
from ._mirror import compensated_deviations as compensated_deviations
