"""Status codes: why a solution or a protection level could not be computed.

Failures are data (DESIGN.md): a batch never raises; the protection level is ``inf`` and the
status says why. Codes are small integers so they live in integer arrays beside the results.
When several reasons apply, the lowest non-zero code is reported, except INVALID_INPUT,
which overrides every other.
"""

import enum


class Status(enum.IntEnum):
    """Why a result could not be computed, one small integer per epoch or geometry beside
    the result (stored as int8); 0 is success. ``describe`` gives the readable name."""

    #: the result was computed
    OK = 0
    #: fewer valid sources than states + 1: no redundancy, so no fault can be detected
    TOO_FEW_SOURCES = 1
    #: the weighted normal matrix is singular to working precision (degenerate geometry)
    SINGULAR_GEOMETRY = 2
    #: a valid source has no redundancy (S_ii ~ 0): a fault on it cannot be detected
    UNDETECTABLE_FAULT = 3
    #: the iterated least squares did not meet its step tolerance in the fixed iteration count
    NOT_CONVERGED = 4
    #: the probability of the fault modes left unmonitored (too many simultaneous faults for
    #: the mode order allowed, or fault-tolerant subsets that are singular) exceeds P_thresh
    #: (seed 004 eq. 8)
    UNMONITORED_RISK = 5
    #: a fault was detected and no candidate subset passed its own test (``detect_and_exclude``)
    EXCLUSION_FAILED = 6
    #: an input of a valid source is unusable (a non-finite or non-unit line-of-sight row, a
    #: non-finite residual, a variance, bias or prior out of range): nothing is claimed, no
    #: detection, no exclusion. Overrides every other code. The host wrappers raise instead
    INVALID_INPUT = 7


def describe(code: int) -> str:
    """Human-readable name of a status code."""
    return Status(int(code)).name.lower().replace("_", " ")
