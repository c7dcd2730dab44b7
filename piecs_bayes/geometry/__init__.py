"""Geometry of turned profiles: pure, differentiable JAX functions; no files, no fits."""

from .. import _config  # noqa: F401  (float64 before any JAX array)
from ._clearance import CHORD_ERROR_MM as CHORD_ERROR_MM
from ._clearance import ball_centres as ball_centres
from ._clearance import feature_polyline as feature_polyline
from ._clearance import path_distance as path_distance
from ._clearance import point_distance as point_distance
from ._clearance import probe_window as probe_window
from ._curves import Arc as Arc
from ._curves import Feature as Feature
from ._curves import Line as Line
from ._curves import left_normal as left_normal
from ._curves import rotate as rotate
from ._drawn import TOLERANCE_ON as TOLERANCE_ON
from ._drawn import drawn_limits as drawn_limits
from ._drawn import drawn_scale as drawn_scale
from ._drawn import feature_form as feature_form
from ._drawn import normal_limits as normal_limits
from ._drawn import tolerance_choices as tolerance_choices
from ._intersect import intersect_circle_circle as intersect_circle_circle
from ._intersect import intersect_line_circle as intersect_line_circle
from ._intersect import intersect_line_line as intersect_line_line
from ._iso2768 import ISO2768_CLASSES as ISO2768_CLASSES
from ._iso2768 import GeneralTolerance as GeneralTolerance
from ._iso2768 import iso2768_tolerance as iso2768_tolerance
from ._profile import Profile as Profile
from ._profile import ProfileError as ProfileError
from ._profile import make_feature as make_feature
from ._profile import profile_side as profile_side
from ._transform import MachineTransform as MachineTransform
from ._transform import ball_correction as ball_correction
from ._transform import machine_to_part as machine_to_part
from ._transform import part_to_machine as part_to_machine
