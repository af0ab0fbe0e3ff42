"""No compensation of the sensor: physics alone (emissivity, reflections and the air at each
pixel's distance), the VOx effect left in. What the pipeline does without a model file, and
the baseline both compensations are measured against."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

from numpy.typing import ArrayLike

from ..conditions import Conditions, ConditionsSchema, Radiometry
from ..radiometry import PAPER_2022, PlanckConstants
from ..schema import PlanckSchema, StrictSchema
from .base import Compensated, Flag, FloatArray, invalid_flag


@dataclass(frozen=True)
class NoCompensation:
    """Radiometry at the true distance and nothing more (the ``none`` method).

    planck: the constants readings are converted with (:meth:`apply`); conditions: those of
    readings that leave them out.
    """

    planck: PlanckConstants = PAPER_2022
    conditions: Conditions = field(default_factory=Conditions)
    method: ClassVar[str] = "none"
    #: the VOx temperature does not enter
    vox_reference_c: ClassVar[float | None] = None
    vox_range_c: ClassVar[tuple[float, float] | None] = None

    @classmethod
    def fit(
        cls,
        table: object = None,
        conditions: Conditions | None = None,
        reference_temp_c: float | None = None,
    ) -> NoCompensation:
        """Nothing to fit: the physics holds for any sweep (and any reference)."""
        return cls(conditions=conditions or Conditions())

    def radiometry(
        self, conditions: Conditions, planck: PlanckConstants | None, method: str
    ) -> Radiometry:
        return Radiometry(conditions, planck or self.planck, method)

    def from_counts(
        self, counts: ArrayLike, vox_c: ArrayLike, distance_m: ArrayLike, radiometry: Radiometry
    ) -> Compensated:
        """The radiometry at ``distance_m`` (a whole frame in one pass where it applies)."""
        fast = radiometry.frame(counts, distance_m, flag_bits=(0, 0, Flag.INVALID, 0))
        if fast is not None:
            return Compensated(*fast)
        temp = radiometry.celsius(counts, distance_m)
        return Compensated(temp, invalid_flag(temp))

    def apply(
        self,
        measured_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        conditions: Conditions | None = None,
    ) -> Compensated:
        """The readings corrected for the air at ``distance_m`` only (their counts read
        again at the true distance)."""
        radiometry = Radiometry(conditions or self.conditions, self.planck)
        return self.from_counts(radiometry.counts(measured_c), vox_c, distance_m, radiometry)

    def predict_measured(
        self,
        true_c: ArrayLike,
        vox_c: ArrayLike,
        distance_m: ArrayLike,
        conditions: Conditions | None = None,
    ) -> FloatArray:
        """What the air alone makes of a target at ``true_c`` read without distance
        correction."""
        radiometry = Radiometry(conditions or self.conditions, self.planck)
        return radiometry.celsius(radiometry.counts(true_c, distance_m))

    def summary(self) -> list[str]:
        return ["no compensation of the VOx temperature: physics at each distance only"]

    def to_dict(self) -> dict[str, Any]:
        return {"planck": PlanckSchema.of(self.planck), "conditions": self.conditions.as_dict()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> NoCompensation:
        p = NoCompensationSchema.model_validate(data)
        return cls(p.planck.constants(), p.conditions.conditions())


class NoCompensationSchema(StrictSchema):
    planck: PlanckSchema = PlanckSchema(**PlanckSchema.of(PAPER_2022))
    conditions: ConditionsSchema = ConditionsSchema()
