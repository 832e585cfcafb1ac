"""Identification of the large-motion model (Gong et al. 2002, eq. 3-5) and of the Dahl
hysteresis (eq. 6-7) from recordings.

Least squares on eq. (4)::

    from servo.identify import robust_regression, paper_regression, least_squares
    reg = robust_regression(rec.t, rec.x, rec.u, rec.dt, terms=("J", "B", "Fc", "h0"))
    fit = least_squares(reg)          # fit["J"], fit.std, fit.cond, fit.rel_error_pct

:func:`identify` does the same from a :class:`~servo.io.recording.Recording` and a path name;
:func:`fit_dahl` fits eq. (6-7) to a current-vs-position loop.
Every function takes arrays and a sample period and returns a frozen dataclass; problems
the data cannot solve raise :class:`IdentificationError` (a
:class:`~servo.errors.ServoError`: one line on the command line).
"""
from servo.identify.dahl_fit import DahlFit, dahl_response, fit_dahl
from servo.identify.least_squares import LSResult, check_identifiable, least_squares
from servo.identify.regressors import (
    COLUMN, TERMS, UNITS, IdentificationError, Regression, RobustSettings, lag_force, matlab_decimate,
    paper_regression, parse_terms, regressor, robust_regression, units,
)  # fmt: skip
from servo.identify.identification import Identification, identify

__all__ = [
    "COLUMN", "TERMS", "UNITS", "DahlFit", "Identification", "IdentificationError", "LSResult", "Regression",
    "RobustSettings", "check_identifiable", "dahl_response", "fit_dahl", "identify", "lag_force", "least_squares",
    "matlab_decimate",
    "paper_regression", "parse_terms", "regressor", "robust_regression", "units",
]

from servo._callable import make_callable  # noqa: E402

make_callable(__name__, "servo.identify.identification:identify")  # servo.identify(...): the notebook entry point
