"""The optimizer: the regularized soft IK and its adjoint gradient
(:mod:`.soft_ik`) and the L0 homotopy's stages (:mod:`.homotopy`)."""

from .._lazy import lazy_exports

__getattr__, __dir__, __all__ = lazy_exports(__name__, {
    ".soft_ik": ("SoftIK", "PoseSolve", "Figures", "Iterate", "pose_errors", "active_set", "state_solver",
                 "ADJOINT_TOL", "EVAL_TOL", "STATE_TOL"),
    ".homotopy": ("StageResult", "RunCallbacks", "run_stage", "run_schedule", "settled", "stage_k",
                  "schedule_done"),
})
