"""The machine model: a validated scene assembled into an immutable model with its right-hand side."""

from mech_regulator.model.machine import LoadPiece, MachineModel, build_model, crank_moments

__all__ = ["LoadPiece", "MachineModel", "build_model", "crank_moments"]
