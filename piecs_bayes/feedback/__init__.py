"""Part-to-part feedback: the tracker (a grid of local-level and drift models), its
filter and mixtures, the policies (bayes and the shop's anchors) and their replay."""

from .. import _config  # noqa: F401  (float64 before any JAX array)
from ._policies import BAYES_DECISION as BAYES_DECISION
from ._policies import COMPARISONS as COMPARISONS
from ._policies import POLICIES as POLICIES
from ._policies import SHOP_SETTINGS as SHOP_SETTINGS
from ._policies import TUNING_GRIDS as TUNING_GRIDS
from ._policies import PolicyResult as PolicyResult
from ._policies import at_measured as at_measured
from ._policies import next_part as next_part
from ._policies import predictive_coverage as predictive_coverage
from ._policies import replay as replay
from ._policies import replay_runs as replay_runs
from ._policies import tune as tune
from ._replay import expand_sampled as expand_sampled
from ._tracking import GRID_LOG_PRIOR as GRID_LOG_PRIOR
from ._tracking import HYPER_GRID as HYPER_GRID
from ._tracking import Track as Track
from ._tracking import TrackModel as TrackModel
from ._tracking import fit_track_model as fit_track_model
from ._tracking import fit_transfer as fit_transfer
from ._tracking import track as track
