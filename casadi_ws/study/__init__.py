"""Design studies: vary a problem's keys, compute each design's workspace, find the designs that reach most."""

from .run import StudyResult, TrialRecord, run_study
from .spec import MEASURES, Objective, Study, StudyError, Variable, load_study, study_from_dict

__all__ = ["MEASURES", "Objective", "Study", "StudyError", "StudyResult", "TrialRecord", "Variable", "load_study",
           "run_study", "study_from_dict"]
