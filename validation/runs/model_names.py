"""The calibration models by name (``--model``; docs/cli.md "Which model calibrates"), apart
from ``model_correction`` so that the command line reads them without importing the model.

- "paper": Eq. 1-8 as written (closed-form chains, no second-order terms);
- "second-order": FEM-informed chains with the second-order terms added to the pose
  (docs/model.md 7-8; the default of ``diagnose`` and ``compensate``, and of every calibration
  command before session 20);
- "consistent": compliance factors following the dimensions, the chains' measured shortening
  solved inside the fixed point with the clearance, the clearance's play state
  (docs/model.md 9-10; the default of ``verify``, ``identify``, ``sensitivity`` and ``design``
  since session 20, ``cli.options.DEFAULT_MODEL``).
"""

__all__ = ["MODELS", "MODEL_STIFFNESS", "FEM_STIFFNESS", "DEFAULT_BREAKAWAY_N"]

MODELS = ("paper", "second-order", "consistent")
# The chain compliance of "second-order" and "consistent" (``--model-stiffness``, the names of the
# providers they come from, ``prototype.providers.PROVIDERS``): corrected by the virtual
# prototype's FEM segments joined through the cut fields ("fem", the default truth's since
# session 25; docs/model.md 7 "Session 25"), or joined rigidly at the cuts ("fem-rigid", the
# provider fem-rigid's, the truth until session 24), or Eq. 1's closed form ("closed-form")
MODEL_STIFFNESS = ("fem", "fem-rigid", "closed-form")
FEM_STIFFNESS = ("fem", "fem-rigid")  # the ones with FEM factors (and their slopes and dimension terms)
# [N] the consistent model's breakaway force when none is given: the virtual prototype's
# default (validation.prototype.scenario, [transmission] breakaway_force_n). Given, not
# identified; the form error moves by <= 0.01 urad between 0.5, 2 and 5 N (docs/model.md 9)
DEFAULT_BREAKAWAY_N = 2.0
