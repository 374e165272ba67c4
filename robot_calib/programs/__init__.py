"""Robot programs in and out: one module per language (KUKA KRL, ABB RAPID, FANUC TP,
Universal Robots URScript) behind one interface (`language.Language`); `source` holds
what a read program is, `configuration` the arm postures the vendors' configuration data
encode (msgs_doc/programs.md)."""

from robot_calib.programs.language import Language
from robot_calib.programs.registry import language_for, language_names
from robot_calib.programs.source import Frame, Program, Target

__all__ = ["Frame", "Language", "Program", "Target", "language_for", "language_names"]
