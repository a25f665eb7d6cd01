"""The orders of a scenario (`demand:`): a Poisson rate with its time-of-day profile, or an
order trace; the flows between stations, plain or multi-stop (fleet_sim.config.chains)."""

from __future__ import annotations

from typing import Final, Literal

from pydantic import Field, model_validator

from fleet_sim.config.chains import MAX_STOPS, MIN_STOPS
from userfiles.checking import HourOfDay, Items, NonNegative, Positive, Problem, StrictModel, Text

MAX_RATE_PER_HOUR: Final = 100_000.0
"""Highest order rate: ~28 orders a second is beyond any AGV warehouse and would flood memory."""


class Flow(StrictModel):
    """An order flow: plain orders from one pickup to one dropoff (`from`, `to`), or chains of
    stops (`stops`, fleet_sim.config.chains), one or the other."""

    from_station: Text | None = Field(default=None, alias="from")
    to_station: Text | None = Field(default=None, alias="to")
    weight: Positive = 1.0
    stops: Items[Text] = ()
    """A multi-stop order: stations alternating pickup, dropoff, pickup, dropoff... (an even
    number, 2 to 20); empty: the plain order `from` -> `to`."""

    @model_validator(mode="after")
    def _from_to_or_stops(self) -> Flow:
        if self.stops:
            if self.from_station is not None or self.to_station is not None:
                raise Problem("stops", list(self.stops), "either from and to, or stops, not both")
            if not MIN_STOPS <= len(self.stops) <= MAX_STOPS or len(self.stops) % 2:
                raise Problem("stops", list(self.stops),
                              f"an even number of stops from {MIN_STOPS} to {MAX_STOPS} "
                              "(pickup, dropoff, pickup, dropoff...)")
        elif self.from_station is None or self.to_station is None:
            missing = "from" if self.from_station is None else "to"
            raise Problem(missing, None, "a station (a flow has from and to, or stops)")
        return self

    @property
    def chain(self) -> tuple[str, ...]:
        """The flow's stops: `stops`, or (from, to)."""
        if self.stops:
            return self.stops
        assert self.from_station is not None and self.to_station is not None
        return (self.from_station, self.to_station)


class RatePeriod(StrictModel):
    from_h: HourOfDay
    """Time of day (hours, 0-24) from which `multiplier` applies, until the next period."""
    multiplier: NonNegative


class DemandConfig(StrictModel):
    kind: Literal["poisson", "trace"] = "poisson"
    rate_per_hour: float = Field(default=60.0, ge=0, le=MAX_RATE_PER_HOUR)
    """Mean orders per hour at multiplier 1 (poisson)."""
    flows: Items[Flow] = ()
    """Order flows between stations; empty: every pickup to every dropoff, equal weights."""
    profile: Items[RatePeriod] = ()
    """Time-of-day rate multipliers, repeating daily; empty: constant rate."""
    trace_csv: Text | None = None
    """Order trace (columns time_s, pickup, dropoff), relative to the scenario file."""

    @model_validator(mode="after")
    def _consistent(self) -> DemandConfig:
        if self.kind == "trace" and self.trace_csv is None:
            raise Problem("trace_csv", None,
                          "the path of an order trace CSV when kind is 'trace'")
        hours = [p.from_h for p in self.profile]
        if hours and (hours[0] != 0 or hours != sorted(set(hours))):
            raise Problem("profile", hours, "periods in increasing from_h, the first at 0")
        return self

    def multiplier_at(self, hour_of_day: float) -> float:
        value = 1.0
        for period in self.profile:
            if period.from_h <= hour_of_day:
                value = period.multiplier
        return value

    @property
    def max_multiplier(self) -> float:
        return max((p.multiplier for p in self.profile), default=1.0)
