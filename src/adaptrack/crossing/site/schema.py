"""The site file format (TOML): a strict schema, and readable errors.

Every table of a site file is described by one model below; a key that is unknown or
misspelt, a value of the wrong type (``true`` or ``"1.5"`` where a number is expected) or out
of range is an error that names its place in the file (``radars[0].range_std_m``) and, for
a misspelt key, the nearest valid one. :func:`validate_site_mapping` returns the validated
:class:`SiteFile`; :mod:`adaptrack.crossing.site.model` builds the site objects from it and checks
the cross-references (names of roads, radars, classes). ``docs/site-format.md`` documents the
format with a commented example.

Noise and detection curves are a number (constant) or a list of ``[argument, value]`` points,
linear in between and constant beyond the ends.
"""

from __future__ import annotations

import difflib
import itertools
import math
import typing
from typing import Annotated, Any, Literal

from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    model_validator,
)

from .traffic import MAX_DECEL_MPS2

CurvePoints = tuple[tuple[float, float], ...]


def _to_points(value: Any) -> Any:
    """Turn a number into one point and lists of pairs into tuples (validated after)."""
    if isinstance(value, bool):
        return value  # rejected by the strict float check
    if isinstance(value, int | float):
        return ((0.0, value),)
    if isinstance(value, list | tuple):
        out = []
        for p in value:
            if not isinstance(p, list | tuple) or len(p) != 2:
                raise ValueError(
                    f"expected a number or a list of [argument, value] pairs; got an item {p!r}"
                )
            out.append(tuple(p))
        return tuple(out)
    return value


def _check_points(points: CurvePoints, positive: bool) -> CurvePoints:
    if not points:
        raise ValueError("needs at least one point")
    xs = [p[0] for p in points]
    if any(not math.isfinite(v) for p in points for v in p):
        raise ValueError(f"points must be finite; got {list(points)}")
    if any(b <= a for a, b in itertools.pairwise(xs)):
        raise ValueError(f"arguments must be strictly increasing; got {xs}")
    if positive and any(p[1] <= 0 for p in points):
        raise ValueError(f"values must be > 0; got {[p[1] for p in points]}")
    if not positive and any(not 0 <= p[1] <= 1 for p in points):
        raise ValueError(f"probabilities must lie in [0, 1]; got {[p[1] for p in points]}")
    return points


StdCurve = Annotated[
    CurvePoints, BeforeValidator(_to_points), AfterValidator(lambda p: _check_points(p, True))
]
ProbabilityCurve = Annotated[
    CurvePoints, BeforeValidator(_to_points), AfterValidator(lambda p: _check_points(p, False))
]
Name = Annotated[str, Field(min_length=1)]
Positive = Annotated[float, Field(gt=0)]
NonNegative = Annotated[float, Field(ge=0)]


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", strict=True, frozen=True)


def _only(model: BaseModel, kind: str, allowed: set[str]) -> None:
    """Reject keys that the element or case kind does not use."""
    given = {k for k, v in model.__dict__.items() if v is not None and k in model.model_fields_set}
    extra = sorted(given - allowed - {"kind", "name", "road", "classes"})
    if extra:
        raise ValueError(f"{', '.join(map(repr, extra))} not used by kind {kind!r}")


class RoadElementFile(_Strict):
    """One piece of a road centreline.

    ``straight`` (``length_m``), ``clothoid`` (``length_m``, curvature ramping to
    ``end_curvature_per_m``, positive to the right) or ``arc`` (``radius_m``, ``turn``, and
    ``length_m`` or ``angle_deg``).
    """

    kind: Literal["straight", "clothoid", "arc"]
    length_m: Positive | None = None
    angle_deg: Positive | None = None
    radius_m: Positive | None = None
    end_curvature_per_m: float | None = None
    turn: Literal["left", "right"] | None = None

    @model_validator(mode="after")
    def _by_kind(self) -> RoadElementFile:
        if self.kind == "straight":
            _only(self, "straight", {"length_m"})
            if self.length_m is None:
                raise ValueError("a straight needs length_m")
        elif self.kind == "clothoid":
            _only(self, "clothoid", {"length_m", "end_curvature_per_m"})
            if self.length_m is None or self.end_curvature_per_m is None:
                raise ValueError("a clothoid needs length_m and end_curvature_per_m")
        else:
            _only(self, "arc", {"length_m", "angle_deg", "radius_m", "turn"})
            if self.radius_m is None or self.turn is None:
                raise ValueError("an arc needs radius_m and turn ('left' or 'right')")
            if (self.length_m is None) == (self.angle_deg is None):
                raise ValueError("an arc needs one of length_m and angle_deg")
        return self


Coordinate = Annotated[float, Field(allow_inf_nan=False)]
Point = Annotated[list[Coordinate], Field(min_length=2, max_length=2)]


class RoadFile(_Strict):
    """A road leaving its crossing end, by elements or by surveyed points.

    Elements from ``start_m`` (default: the crossing centre) with ``heading_deg``, or
    surveyed centreline points ``points_m`` (the first at the crossing end).
    ``lanes_in``/``lanes_out``: lanes towards the crossing end and away from it;
    ``stop_line_m``/``barrier_m``: this road's (default: the site's); ``extend_m``: a
    straight beyond the last surveyed point; ``survey_std_m``: smoothing of the points.
    """

    name: Name
    heading_deg: float | None = None
    elements: Annotated[list[RoadElementFile], Field(min_length=1)] | None = None
    start_m: Point | None = None
    points_m: Annotated[list[Point], Field(min_length=2)] | None = None
    extend_m: NonNegative = 0.0
    survey_std_m: NonNegative = 0.05
    lanes_in: Annotated[int, Field(ge=1, le=8)] = 1
    lanes_out: Annotated[int, Field(ge=0, le=8)] = 1
    stop_line_m: NonNegative | None = None
    barrier_m: NonNegative | None = None
    radar: Name | None = None  # the radar that tracks this road (default: the best coverage)

    @model_validator(mode="after")
    def _one_form(self) -> RoadFile:
        if self.points_m is not None:
            if self.elements is not None or self.heading_deg is not None:
                raise ValueError("give points_m, or heading_deg with elements; not both")
            if self.start_m is not None:
                raise ValueError("start_m is for elements (points_m starts at its first point)")
        else:
            if self.elements is None or self.heading_deg is None:
                raise ValueError("needs heading_deg and elements, or points_m")
            if "extend_m" in self.model_fields_set or "survey_std_m" in self.model_fields_set:
                raise ValueError("extend_m and survey_std_m are for points_m")
        return self


class ConnectionFile(_Strict):
    """A turning path from road ``entry`` onto road ``exit`` through surveyed lane points.

    ``points_m``: the centre of the lane the turning traffic drives, in its direction;
    without it the path is a smooth turn of the default radius.
    """

    entry: Name
    exit: Name
    points_m: Annotated[list[Point], Field(min_length=2)] | None = None


class RailsFile(_Strict):
    """The railway: its axis through ``centre_m`` with azimuth ``axis_deg``, its tracks."""

    axis_deg: float
    centre_m: Point = Field(default_factory=lambda: [0.0, 0.0])
    tracks: Annotated[int, Field(ge=1, le=8)] = 1
    track_spacing_m: Positive = 4.5
    gauge_m: Positive = 1.435


class FieldFile(_Strict):
    """One field of view: slant ranges up to ``max_range_m`` within ``+-fov_half_deg``."""

    max_range_m: Positive
    fov_half_deg: Annotated[float, Field(gt=0, le=180)]


class RadarFile(_Strict):
    """A radar: pose, scan, fields of view, noise curves, gates and detection probability.

    ``range_std_m`` and ``radial_speed_std_mps`` are functions of the slant range [m];
    ``azimuth_std_deg`` of the angle off boresight [deg]; ``detection_probability`` maps a
    class name (or ``default``) to a probability against slant range [m].
    """

    name: Name
    position_m: Annotated[list[float], Field(min_length=2, max_length=2)]
    boresight_deg: float
    period_s: Positive
    range_std_m: StdCurve
    azimuth_std_deg: StdCurve
    radial_speed_std_mps: StdCurve
    height_m: NonNegative = 6.0
    fov_half_deg: Annotated[float, Field(gt=0, le=180)] | None = None
    max_range_m: Positive | None = None
    fields: Annotated[list[FieldFile], Field(min_length=1)] | None = None
    min_range_m: NonNegative = 0.5
    min_radial_speed_mps: NonNegative = 0.1
    detection_probability: dict[Name, ProbabilityCurve] = Field(
        default_factory=lambda: {"default": _to_points(0.95)}
    )
    azimuth_bias_deg: float = 0.0
    time_jitter_s: NonNegative = 0.0
    max_unambiguous_speed_mps: Positive | None = None
    latency_s: Annotated[float, Field(ge=-1.0, le=1.0)] = 0.0

    @model_validator(mode="after")
    def _one_field_form(self) -> RadarFile:
        short = (self.fov_half_deg, self.max_range_m)
        if self.fields is not None and any(v is not None for v in short):
            raise ValueError("give either fields or fov_half_deg and max_range_m, not both")
        if self.fields is None and None in short:
            raise ValueError("needs fields, or fov_half_deg and max_range_m")
        return self


class ClassFile(_Strict):
    """A road-user class: dimensions, kinematic limits and reflection-point scatter.

    For a built-in class (motorcycle, car, truck, bus) every key is optional and overrides
    the built-in value; a new class needs all but ``scatter_std_m`` (default 0.15 length).
    """

    length_m: Positive | None = None
    width_m: Positive | None = None
    accel_mps2: Positive | None = None
    decel_mps2: Positive | None = None
    emergency_decel_mps2: Annotated[float, Field(gt=0, le=MAX_DECEL_MPS2)] | None = None
    max_speed_kmh: Positive | None = None
    scatter_std_m: NonNegative | None = None


class TrafficFile(_Strict):
    """The traffic mix: the share of each class.

    The shares sum to 1; classes absent from the mix are not evaluated.
    """

    mix: Annotated[dict[Name, Annotated[float, Field(gt=0, le=1)]], Field(min_length=1)]

    @model_validator(mode="after")
    def _sums_to_one(self) -> TrafficFile:
        total = sum(self.mix.values())
        if abs(total - 1.0) > 1e-6:
            raise ValueError(f"the shares of mix must sum to 1; they sum to {total:g}")
        return self


def _check_knots(points: CurvePoints) -> None:
    """Speed knots ``[time_s, speed_kmh]``: from time 0, increasing, at most MAX_DECEL apart."""
    if len(points) < 2 or points[0][0] != 0.0:
        raise ValueError("needs at least two [time_s, speed_kmh] knots, the first at time 0")
    if any(b[0] <= a[0] for a, b in itertools.pairwise(points)):
        raise ValueError("knot times must be strictly increasing")
    if any(not math.isfinite(v) for _, v in points):
        raise ValueError("speeds must be finite")
    for a, b in itertools.pairwise(points):
        accel = abs(b[1] - a[1]) / 3.6 / (b[0] - a[0])
        if accel > MAX_DECEL_MPS2:
            raise ValueError(
                f"{accel:.3g} m/s^2 between {a[0]:g} s and {b[0]:g} s; at most "
                f"{MAX_DECEL_MPS2:g} m/s^2"
            )


def _check_profile(points: CurvePoints) -> CurvePoints:
    _check_knots(points)
    if any(v < 0 for _, v in points):
        raise ValueError("speeds must be >= 0")
    if points[0][1] <= 0:
        raise ValueError("the first knot's speed must be > 0 (the vehicle approaches)")
    return points


class CaseFile(_Strict):
    """An approach script on one road (kinds as in :mod:`adaptrack.crossing.site.traffic`)."""

    name: Name
    road: Name
    kind: Literal["pass", "stop", "emergency", "random", "profile"]
    speed_kmh: Positive | None = None
    dwell_s: NonNegative | None = None
    decel_mps2: Annotated[float, Field(gt=0, le=MAX_DECEL_MPS2)] | None = None
    jerk_mps3: Positive | None = None
    stop_at_m: NonNegative | None = None
    speed_profile: (
        Annotated[CurvePoints, BeforeValidator(_to_points), AfterValidator(_check_profile)] | None
    ) = None
    time_constant_s: Positive | None = None
    accel_std_mps2: Positive | None = None
    classes: Annotated[list[Name], Field(min_length=1)] | None = None

    @model_validator(mode="after")
    def _by_kind(self) -> CaseFile:
        uses = {
            "pass": {"speed_kmh"},
            "stop": {"speed_kmh", "dwell_s", "decel_mps2", "jerk_mps3", "stop_at_m"},
            "random": {"speed_kmh", "time_constant_s", "accel_std_mps2"},
            "profile": {"speed_profile"},
        }
        kind = "stop" if self.kind == "emergency" else self.kind
        _only(self, self.kind, uses[kind])
        if self.kind == "profile" and self.speed_profile is None:
            raise ValueError("a profile case needs speed_profile")
        if self.kind != "profile" and self.speed_kmh is None:
            raise ValueError(f"a {self.kind!r} case needs speed_kmh")
        return self


class FlowFile(_Strict):
    """Traffic entering on road ``entry`` and leaving on ``exit``: Poisson arrivals per hour."""

    entry: Name
    exit: Name
    vehicles_per_h: NonNegative


class StallFile(_Strict):
    """A vehicle that stalls between the barriers.

    The first vehicle from ``entry`` after ``time_s`` stops ``at_m`` before the crossing
    centre (negative: past it) and stays ``duration_s``.
    """

    entry: Name
    time_s: NonNegative
    at_m: float = 0.0
    duration_s: Positive = 180.0
    vehicle_class: Name = "car"


class ParkedFile(_Strict):
    """A road user standing from ``from_s`` to ``until_s`` (a parked car, a fallen load)."""

    position_m: Point
    heading_deg: float = 0.0
    vehicle_class: Name = "car"
    length_m: Positive | None = None
    width_m: Positive | None = None
    from_s: NonNegative = 0.0
    until_s: Positive | None = None


def _check_scripted_profile(points: CurvePoints) -> CurvePoints:
    _check_knots(points)
    return points


class ScriptedFile(_Strict):
    """A road user driven along ``path_m`` by ``speed_profile`` from ``start_s``.

    ``speed_profile``: ``[[time_s, speed_kmh], ...]`` from 0, linear between knots; the user
    travels the path from its first point, facing backwards while the speed is negative
    (reversing); it leaves the scene after its last knot or at the end of the path.
    Emergency stops, overtaking, U-turns and reversing off the crossing are such scripts.
    """

    path_m: Annotated[list[Point], Field(min_length=2)]
    speed_profile: Annotated[
        CurvePoints, BeforeValidator(_to_points), AfterValidator(_check_scripted_profile)
    ]
    start_s: NonNegative = 0.0
    vehicle_class: Name = "car"
    length_m: Positive | None = None
    width_m: Positive | None = None


class TrainFile(_Strict):
    """Trains passing between the barriers at every closure (needs the site's rails)."""

    length_m: Positive = 150.0
    width_m: Positive = 3.2
    height_m: Positive = 4.2
    speed_kmh: Positive = 80.0
    run_m: Positive = 300.0  # each train is simulated this far either side of the centre


class SceneFile(_Strict):
    """Mixed traffic for the many-object scene (:mod:`adaptrack.crossing.simulation.scene`).

    ``mix`` gives the share of each road-user class in the flows (default: the site's traffic
    mix); ``pedestrian`` and ``cyclist`` are known besides the vehicle classes. Barriers close
    for ``closure_s`` every ``closure_every_s`` (first at ``first_closure_s``).
    """

    duration_s: Positive = 3600.0
    flows: Annotated[list[FlowFile], Field(min_length=1)] | None = None
    mix: dict[Name, Annotated[float, Field(gt=0, le=1)]] | None = None
    closure_every_s: Positive = 600.0
    closure_s: NonNegative = 120.0
    first_closure_s: NonNegative = 300.0
    false_alarms_per_scan: NonNegative = 0.5
    static_clutter_m: list[Annotated[list[float], Field(min_length=2, max_length=2)]] = Field(
        default_factory=list
    )
    multipath_probability: Annotated[float, Field(ge=0, le=1)] = 0.01
    multipath_extra_m: Positive = 8.0
    occlusion: bool = True
    stationary_detections: bool = True
    stalls: list[StallFile] = Field(default_factory=list)
    parked: list[ParkedFile] = Field(default_factory=list)
    scripted: list[ScriptedFile] = Field(default_factory=list)
    trains: TrainFile | None = None


class SiteFile(_Strict):
    """A level-crossing site: geometry, radars, road users and the cases to check."""

    roads: Annotated[list[RoadFile], Field(min_length=1)]
    radars: Annotated[list[RadarFile], Field(min_length=1)]
    name: Name | None = None
    description: str = ""
    lane_width_m: Positive = 3.5
    barrier_m: NonNegative = 10.0
    stop_line_m: NonNegative = 15.0
    zone_m: Positive = 150.0
    run_in_m: NonNegative = 50.0
    lateral_offset_std_m: NonNegative = 0.3
    classes: dict[Name, ClassFile] = Field(default_factory=dict)
    traffic: TrafficFile | None = None
    cases: Annotated[list[CaseFile], Field(min_length=1)] | None = None
    scene: SceneFile | None = None
    connections: list[ConnectionFile] = Field(default_factory=list)
    rails: RailsFile | None = None


def validate_site_mapping(data: dict[str, Any], where: str) -> SiteFile:
    """Validate a parsed site file; the first problem raises ``ValueError`` naming its place."""
    try:
        return SiteFile.model_validate(data)
    except ValidationError as exc:
        raise ValueError(f"{where}: {_describe(exc.errors()[0])}") from None


def _describe(error: Any) -> str:
    loc = [p for p in error["loc"] if not (isinstance(p, str) and "[" in p)]  # union branches
    place = "".join(f"[{p}]" if isinstance(p, int) else f".{p}" for p in loc).lstrip(".")
    if error["type"] == "extra_forbidden":
        key = str(loc[-1])
        known = _keys_at(loc[:-1])
        near = difflib.get_close_matches(key, known, n=1, cutoff=0.6)
        hint = f" (did you mean {near[0]!r}?)" if near else f"; known keys: {', '.join(known)}"
        parent = place[: -len(key)].rstrip(".") or "the site"
        return f"{parent}: unknown key {key!r}{hint}"
    if error["type"] == "missing":
        parent = place[: -len(str(loc[-1]))].rstrip(".") or "the site"
        return f"{parent}: missing key {loc[-1]!r}"
    msg = str(error["msg"]).removeprefix("Value error, ")
    got = error.get("input")
    shown = "" if isinstance(got, dict | list) or got is None else f" (got {got!r})"
    return f"{place or 'the site'}: {msg}{shown}"


def _keys_at(loc: list[Any]) -> list[str]:
    """Field names of the schema model at a location (for did-you-mean hints)."""
    model: Any = SiteFile
    for part in loc:
        if isinstance(part, int):
            continue
        field = model.model_fields.get(part)
        if field is None:  # a key of a mapping (class name, ...): the value's model
            continue
        model = _model_in(field.annotation)
        if model is None:
            return []
    if isinstance(model, type) and issubclass(model, BaseModel):
        return sorted(model.model_fields)
    return []


def _model_in(annotation: Any) -> type[BaseModel] | None:
    """Find the schema model inside an annotation (list, dict, optional, annotated)."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        found = _model_in(arg)
        if found is not None:
            return found
    return None


__all__ = [
    "CaseFile",
    "ClassFile",
    "ConnectionFile",
    "ParkedFile",
    "RadarFile",
    "RailsFile",
    "RoadFile",
    "ScriptedFile",
    "SiteFile",
    "TrafficFile",
    "TrainFile",
    "validate_site_mapping",
]
