"""What every scene section shares: the base model (unknown keys, NaN and infinities are errors), the positive and
non-negative number types and the check of a periodic table (scene/schema.py describes the format)."""

from __future__ import annotations

from typing import Annotated

from pydantic import BaseModel, ConfigDict, Field

Positive = Annotated[float, Field(gt=0)]
NonNegative = Annotated[float, Field(ge=0)]


class SceneModel(BaseModel):
    """Base of every scene section: unknown keys, NaN and infinities are errors; ints pass as floats."""

    model_config = ConfigDict(extra="forbid", allow_inf_nan=False, strict=True, frozen=True)


def check_table(angles_deg: list[float], values: list[float], period_deg: float, what: str) -> None:
    """Check a periodic table: equal lengths, strictly increasing angles inside one period."""
    if len(angles_deg) != len(values):
        raise ValueError(
            f"{what}: angle_deg has {len(angles_deg)} entries but the values have {len(values)}; "
            "expected one value per angle"
        )
    if any(b <= a for a, b in zip(angles_deg, angles_deg[1:])):
        raise ValueError(f"{what}: angle_deg = {angles_deg} must be strictly increasing")
    if angles_deg[-1] - angles_deg[0] >= period_deg:
        raise ValueError(
            f"{what}: angle_deg spans {angles_deg[-1] - angles_deg[0]} deg; "
            f"expected less than one period ({period_deg} deg)"
        )
