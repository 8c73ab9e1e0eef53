"""The machine model: a validated scene assembled into an immutable model with its right-hand side."""

from mech_regulator.model.building import build_model
from mech_regulator.model.columns import crank_moments
from mech_regulator.model.machine import LoadPiece, MachineModel

__all__ = ["LoadPiece", "MachineModel", "build_model", "crank_moments"]
