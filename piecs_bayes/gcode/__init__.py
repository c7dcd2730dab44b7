"""Part programs (G-code; LinuxCNC, Fanuc, Haas and Okuma dialects): lossless lexing,
control flow and parameters, modal state, tool tables,
tool-nose compensation (G41/G42) and the material side of each run (from the moves in
air), the adjusted finish-cut program (with its traceability
comment block), the finish contour (a study's profile from the program), the tool that
cuts the finish pass, canned cycles (G70/G71/G72/G73 expanded into the control's
moves), and the rs274 bridge.

Builds on `piecs_bayes.geometry` (features of the profile) and `piecs_bayes.errors`;
neither `geometry` nor `io` imports this package.
"""

from .. import _config  # noqa: F401  (float64 before any JAX array)
from ._adjust import BlockChange as BlockChange
from ._adjust import BlockMap as BlockMap
from ._adjust import ProgramAdjustment as ProgramAdjustment
from ._adjust import ToolPath as ToolPath
from ._adjust import adjust_path_program as adjust_path_program
from ._adjust import adjust_program as adjust_program
from ._adjust import map_blocks_to_profile as map_blocks_to_profile
from ._contour import ContourSegment as ContourSegment
from ._contour import FinishContour as FinishContour
from ._contour import compensation_runs as compensation_runs
from ._contour import finish_contour as finish_contour
from ._cycle_words import fanuc_cycle as fanuc_cycle
from ._cycle_words import linuxcnc_cycle as linuxcnc_cycle
from ._cycle_words import non_contour_cycle as non_contour_cycle
from ._cycles import ContourMove as ContourMove
from ._cycles import CycleMove as CycleMove
from ._cycles import FinishCycle as FinishCycle
from ._cycles import RoughCycle as RoughCycle
from ._cycles import cycle_start as cycle_start
from ._cycles import expand_cycle as expand_cycle
from ._dialect import DIALECTS as DIALECTS
from ._dialect import Dialect as Dialect
from ._dialect import DialectTable as DialectTable
from ._dialect import detect_dialect as detect_dialect
from ._dialect import dialect_table as dialect_table
from ._dprnt import DprntFormat as DprntFormat
from ._dprnt import dprnt_value as dprnt_value
from ._gauge_moves import GaugeMove as GaugeMove
from ._gauge_moves import GaugeProgram as GaugeProgram
from ._gauge_moves import gauge_moves as gauge_moves
from ._gauge_moves import read_gauge_program as read_gauge_program
from ._gauging import CONTROLLERS as CONTROLLERS
from ._gauging import GAUGING_NAMES as GAUGING_NAMES
from ._gauging import GaugingOptions as GaugingOptions
from ._gauging import gauging_program as gauging_program
from ._header import comment_style as comment_style
from ._header import comment_text as comment_text
from ._header import diff_labels as diff_labels
from ._header import with_comment_block as with_comment_block
from ._lexer import GcodeText as GcodeText
from ._lexer import SourceLine as SourceLine
from ._lexer import Word as Word
from ._lexer import edit_line as edit_line
from ._lexer import format_number as format_number
from ._lexer import lex_gcode as lex_gcode
from ._material_side import AirWitness as AirWitness
from ._material_side import MaterialSideWarning as MaterialSideWarning
from ._material_side import RunSide as RunSide
from ._material_side import comp_sides as comp_sides
from ._material_side import side_error as side_error
from ._nosecomp import NoseCompResult as NoseCompResult
from ._nosecomp import PathMove as PathMove
from ._nosecomp import compensated_path as compensated_path
from ._nosecomp import correct_radius_error as correct_radius_error
from ._nosecomp import nose_compensate as nose_compensate
from ._nosecomp import tip_offset as tip_offset
from ._options import STEP_LIMIT as STEP_LIMIT
from ._options import ReadOptions as ReadOptions
from ._path_contour import path_contour as path_contour
from ._path_contour import path_targets as path_targets
from ._pattern_repeat import PatternRepeat as PatternRepeat
from ._pattern_repeat import expand_pattern_repeat as expand_pattern_repeat
from ._program import CompEvent as CompEvent
from ._program import CompSetting as CompSetting
from ._program import GcodeProgram as GcodeProgram
from ._program import LineState as LineState
from ._program import Motion as Motion
from ._program import Note as Note
from ._program import ToolWord as ToolWord
from ._read import parse_gcode as parse_gcode
from ._read import read_gcode as read_gcode
from ._rs274 import CanonMove as CanonMove
from ._rs274 import Rs274Result as Rs274Result
from ._rs274 import rs274_path as rs274_path
from ._rs274 import run_rs274 as run_rs274
from ._toolcall import FinishCutTools as FinishCutTools
from ._toolcall import ToolCall as ToolCall
from ._toolcall import finish_cut_tools as finish_cut_tools
from ._toolcall import tool_call as tool_call
from ._tools import ToolEntry as ToolEntry
from ._tools import parse_tool_table as parse_tool_table
from ._tools import read_tool_table as read_tool_table
from ._writer import write_path_program as write_path_program
