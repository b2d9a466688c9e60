"""flexcal.calibration: Sobol screening, the improved multi-subgroup PSO, polish, identifiability, the identification problem.

Public names load on first use (``flexcal.geometry._lazy``).
"""

from __future__ import annotations

from flexcal.geometry._lazy import lazy_exports

_EXPORTS = {
    "CalibrationProblem": "problem",
    "EvaluationLog": "problem",
    "SobolResult": "sensitivity",
    "make_problem": "sensitivity",
    "sobol_indices": "sensitivity",
    "analyze_outputs": "sensitivity",
    "ranked_table": "sensitivity",
    "format_ranked_table": "sensitivity",
    "select_parameters": "sensitivity",
    "ConvergenceReport": "sensitivity_checks",
    "sobol_convergence": "sensitivity_checks",
    "IndexViolation": "sensitivity_checks",
    "check_index_properties": "sensitivity_checks",
    "CrossValidation": "sensitivity_checks",
    "cross_validate": "sensitivity_checks",
    "PSOSettings": "pso",
    "SubgroupRecord": "pso",
    "PSOResult": "pso",
    "MultiSubgroupPSO": "pso",
    "identify": "pso",
    "plain_settings": "pso",
    "PolishResult": "polish",
    "least_squares_polish": "polish",
    "polish_candidates": "polish",
    "batched_jacobian_fd": "polish",
    "EvaluationCounter": "polish",
    "IdentifiabilityReport": "identifiability",
    "LoopSettings": "compensation",
    "LoopRound": "compensation",
    "LoopResult": "compensation",
    "iterate": "compensation",
    "closed_loop": "compensation",
    "correction_step": "compensation",
    "within_tolerance": "compensation",
    "identifiability": "identifiability",
    "analyze_jacobian": "identifiability",
    "plot_sensitivity": "plots",
    "plot_convergence": "plots",
    "ishigami": "testfunctions",
    "ishigami_indices": "testfunctions",
    "ISHIGAMI_BOUNDS": "testfunctions",
    "sobol_g": "testfunctions",
    "sobol_g_indices": "testfunctions",
    "OptimizationProblem": "testfunctions",
    "sphere": "testfunctions",
    "rosenbrock": "testfunctions",
    "rastrigin": "testfunctions",
    "ackley": "testfunctions",
    "schwefel": "testfunctions",
    "LeastSquaresProblem": "testfunctions",
    "curve_fit_problem": "testfunctions",
}

__getattr__, __dir__, __all__ = lazy_exports(__name__, _EXPORTS)
