"""Test helpers shared by several test files (kept independent of the production
counters they check)."""


class Counting:
    """Batched function wrapper counting calls and rows, written separately from
    ``flexcal.calibration.polish.EvaluationCounter`` so tests of that counting are not
    checked against themselves."""

    def __init__(self, function):
        self.function, self.calls, self.rows = function, 0, 0

    def __call__(self, x):
        self.calls += 1
        self.rows += x.shape[0]
        return self.function(x)
