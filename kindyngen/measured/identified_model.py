"""An identified model written back as a robot description (``model.yaml``) that the project's
loader, and any tool reading the documented schema, takes as it is.

The geometry (DH rows, limits, gravity) is copied from the description the identification
started from; the links get the identified inertial parameters (mass, centre of mass, inertia
about the centre of mass in the description's order ``ixx, iyy, izz, ixy, ixz, iyz``), the
joints the identified friction, offset and armature. A payload of the starting description is
already inside identified links (the data cannot tell them apart), so none is written with
them; a discovered payload or base tilt is written as ``payload`` and ``gravity``.

Example:

>>> from kindyngen.measured.consistent import links_from_barycentric
>>> links = links_from_barycentric(full_values, 7)                  # doctest: +SKIP
>>> text = model_yaml("robots/lwr4.yaml", links, {"fv1": 0.5})      # doctest: +SKIP
"""
from __future__ import annotations

import math
from pathlib import Path

import yaml

from ..readers.yaml_writer import describe
from . import MeasuredDataError

EFFECT_FIELDS = {"fv": ("friction", "viscous"), "fc": ("friction", "coulomb"), "f0": ("friction", "offset"),
                 "fs": ("friction", "stribeck"), "vs": ("friction", "stribeck_velocity"), "fl": ("friction", "load"),
                 "rs": ("ripple", "sin"), "rc": ("ripple", "cos"), "rk": ("ripple", "order"),
                 "Ia": ("armature", None), "ce": ("stiffness", None), "dq": ("encoder_offset", None),
                 "gt": ("torque_gain", None)}
#: how a fitted coefficient becomes the description's value: compliance ce = 1 / stiffness,
#: relative gain error gt = torque_gain - 1, a ripple's order a whole number
_CONVERT = {"ce": lambda v: 1.0 / v, "gt": lambda v: 1.0 + v, "rk": lambda v: int(round(v))}


class ModelWriteError(MeasuredDataError):
    """The identified values do not make a valid robot description (named parameter, reason)."""


def model_description(source: str | Path, links: list[dict] | None, effects: dict[str, float],
                      name: str | None = None, payload: dict | None = None, gravity=None, model=None) -> dict:
    """The starting description (file ``source``) with identified links and effects.
    ``links``: new link entries (None keeps the description's links, and its payload);
    ``effects`` maps coefficient names (``fv1``, ``fc1``, ``f01``, ``Ia1``; ``fs1`` and ``vs1``
    the Stribeck friction and velocity, ``fl1`` the load-dependent friction, ``rs1``, ``rc1``,
    ``rk1`` the ripple's sine and cosine amplitudes and order; ``ce1`` a compliance written as
    ``stiffness = 1 / ce1``, ``dq1`` as ``encoder_offset``, ``gt1`` as ``torque_gain = 1 +
    gt1``; 1-based joints) to values, replacing the description's friction, ripple, armature
    and sensing; ``payload``
    (``{mass, com, inertia}``) and ``gravity`` replace the description's when given. A URDF
    ``source`` is written as the YAML of ``model`` (the chain read from it; joints by origin
    and axis, :func:`kindyngen.readers.yaml_writer.describe`)."""
    if Path(source).suffix.lower() == ".urdf":
        if model is None:
            raise ModelWriteError(f"{source}: a URDF is written from its model; pass model=")
        data = describe(model)
    else:
        data = yaml.safe_load(Path(source).read_text())
    if name:
        data["name"] = name
    if links is not None:
        data.pop("payload", None)   # the identified last link already holds it
        if len(links) != len(data["joints"]):
            raise ModelWriteError(f"{len(links)} identified links for {len(data['joints'])} joints")
        data["links"] = [{"mass": l["mass"], "com": list(l["com"]), "inertia": list(l["inertia"])} for l in links]
    if payload is not None:
        data["payload"] = {"mass": float(payload["mass"]), "com": [float(v) for v in payload["com"]],
                           "inertia": [float(v) for v in payload["inertia"]]}
    if gravity is not None:
        data["gravity"] = [float(v) for v in gravity]
    for joint in data["joints"]:
        for key in ("friction", "armature", "ripple", "stiffness", "encoder_offset", "torque_gain"):
            joint.pop(key, None)
    for key, value in effects.items():
        prefix, index = key[:2], int(key[2:]) - 1
        if prefix not in EFFECT_FIELDS or not 0 <= index < len(data["joints"]):
            raise ModelWriteError(f"unknown effect coefficient {key!r}")
        if not math.isfinite(value):
            raise ModelWriteError(f"effect coefficient {key} is {value}")
        if prefix == "ce" and not value > 0:
            raise ModelWriteError(f"compliance {key} = {value:g} is not positive (no finite stiffness)")
        value = _CONVERT.get(prefix, float)(value)
        field, sub = EFFECT_FIELDS[prefix]
        joint = data["joints"][index]
        if sub is None:
            joint[field] = float(value)
        else:
            joint.setdefault(field, {})[sub] = value if isinstance(value, int) else float(value)
    for k, joint in enumerate(data["joints"]):
        if "stribeck" in joint.get("friction", {}) and "stribeck_velocity" not in joint["friction"]:
            raise ModelWriteError(f"fs{k + 1} without its Stribeck velocity vs{k + 1}")
        if "ripple" in joint and "order" not in joint["ripple"]:
            raise ModelWriteError(f"ripple of joint {k + 1} without its order rk{k + 1}")
    return data


def model_yaml(source: str | Path, links: list[dict] | None, effects: dict[str, float], header: str = "",
               name: str | None = None, payload: dict | None = None, gravity=None, model=None) -> str:
    """:func:`model_description` as YAML text (joint rows on one line each, as the shipped
    descriptions are written), with ``header`` as leading comment lines."""
    data = model_description(source, links, effects, name, payload, gravity, model)
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    for key in ("name", "dh", "gravity"):
        lines.append(yaml.safe_dump({key: data[key]}, default_flow_style=True, width=1000).strip().strip("{}"))
    for key in ("joints", "links"):
        lines.append(f"{key}:")
        for row in data[key]:
            lines.append("  - " + yaml.safe_dump(row, default_flow_style=True, sort_keys=False, width=10000).strip())
    for key in data:
        if key not in ("name", "dh", "gravity", "joints", "links"):
            lines.append(yaml.safe_dump({key: data[key]}, default_flow_style=False, sort_keys=False).strip())
    return "\n".join(lines) + "\n"
