"""The report: its vocabulary (`model`), sections, HTML and PDF renderers."""

from ... import _config  # noqa: F401  (float64 before any JAX array)
from ._feedback import feedback_blocks as feedback_blocks
from ._feedback import feedback_report_html as feedback_report_html
from ._feedback import write_feedback as write_feedback
from ._files import report_files as report_files
from ._html import report_html as report_html
from ._html import summary_html as summary_html
from ._pdf import report_pdf as report_pdf
from ._summary import summary_rows as summary_rows
