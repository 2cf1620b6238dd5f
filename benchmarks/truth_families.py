"""What the known-truth benchmark of ``discover`` hides, and how ``discover``'s answer is scored.

One table, :data:`FAMILIES`: each family names the simulator laws it hides
(:mod:`benchmarks.truth_simulator`) and the answer, in ``discover``'s candidate names.  A new
candidate of ``discover`` is one entry here (or a changed ``answer`` / ``in_library`` of one).

**Two scoring rules.**

- *exact* (the effect's law is in discover's library: ``in_library`` and every ``answer`` name is
  a candidate the ``discover`` measured offers, as its ``--candidates`` error lists them): the
  named set must equal ``answer`` (and, where ``discover`` writes a ``drift`` report, the drifting
  effects must equal ``drift``).  A name outside the answer is *spurious*, an answer name not
  named is *missed*.
- *unseen* (an effect outside today's library: another ripple order, errors of the nominal
  inertial parameters, a warm-up drift): the correct answer is the closest storable effect or an
  honest "not explained".  Correct when every named effect is in ``answer`` or ``stand_ins``
  (anything else is spurious) *and* the verdict is right: ``"explained": true`` only when the
  residual really is at the noise floor.  The family turns into an *exact* one by setting
  ``in_library`` once ``discover`` holds the law.

**Verdict.**  The truth of ``"explained"``: the named set is correct (as above) and the held-out
RMS with every fitted effect (``rms_after_all_fitted``) is within :data:`EXPLAINED_FACTOR` of
the trial's true noise floor on every joint (discover's own rule, docs/discovery.md, against the
floor the simulator knows rather than the one discover estimates).

**Coefficients.**  For each correctly named effect, each coefficient that matters (its own
size, :func:`benchmarks.truth_simulator.coefficient_sizes`, at least :data:`SIGNIFICANT`
floors) gives a relative error ``|fitted - true| / |true|``: per joint for the joint laws
(``(rs, rc)`` as one vector), the payload mass, and ``|g_fitted - g_true| / |g_true - g_nominal|``
for a tilt.  The fitted value is the final joint fit's (``model_yaml_values``, then
``not_determined``'s ``fitted``, then the last step that fitted it); none at all counts as 1.

>>> fam = FAMILIES["stribeck_friction"]
>>> fam.laws, fam.answer
(('coulomb', 'stribeck'), ('coulomb_friction', 'stribeck_friction'))
>>> score_names(fam, ["coulomb_friction", "stribeck_friction"], known=CANDIDATES_TODAY)["exact"]
True
>>> score_names(FAMILIES["link_errors"], ["payload"], known=CANDIDATES_TODAY)["scoring"]
'unseen'
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: discover's own verdict factor (docs/discovery.md, "Verdict")
EXPLAINED_FACTOR = 1.5
#: coefficients are scored when their own size is at least this many noise floors
SIGNIFICANT = 3.0
#: the candidates of discover when this benchmark was written (the doctests' reference; the
#: benchmark asks the measured discover for its own list)
CANDIDATES_TODAY = ("viscous_friction", "coulomb_friction", "torque_offset", "armature", "payload", "base_tilt",
                    "stribeck_friction", "position_ripple", "load_dependent_friction", "motor_side_elasticity",
                    "encoder_offset", "torque_sensor_gain")


@dataclass(frozen=True)
class Family:
    name: str
    laws: tuple[str, ...]               # simulator laws hidden (truth_simulator.LAWS)
    answer: tuple[str, ...]             # discover's candidate names that are the exact answer
    in_library: bool = True             # discover's library holds the laws as simulated
    stand_ins: tuple[str, ...] = ()     # unseen families: names accepted in place of the answer
    drift: tuple[str, ...] = ()         # effects that should be reported drifting (when discover reports drift)
    options: dict = field(default_factory=dict)   # per law: options of truth_simulator.draw_shape
    note: str = ""


FAMILIES = {f.name: f for f in (
    Family("none", (), (), note="nothing hidden: the nominal model is right"),
    Family("viscous_friction", ("viscous",), ("viscous_friction",)),
    Family("coulomb_friction", ("coulomb",), ("coulomb_friction",), note="sharp sign(qd)"),
    Family("torque_offset", ("offset",), ("torque_offset",)),
    Family("armature", ("armature",), ("armature",)),
    Family("payload", ("payload",), ("payload",), note="a box of 3 kg at most on the last joint"),
    Family("base_tilt", ("tilt",), ("base_tilt",), note="gravity turned by 5 degrees at most"),
    Family("stribeck_friction", ("coulomb", "stribeck"), ("coulomb_friction", "stribeck_friction"),
           note="the textbook Stribeck curve: Coulomb friction plus the excess at low speed, vs 0.03-0.3 rad/s"),
    Family("position_ripple", ("ripple",), ("position_ripple",), options={"ripple": {"orders": (6,)}},
           note="6 periods per radian, discover's order"),
    Family("load_dependent_friction", ("load",), ("load_dependent_friction",)),
    Family("motor_side_elasticity", ("elastic",), ("motor_side_elasticity",),
           note="peak deflection 0.03 rad at most"),
    Family("encoder_offset", ("encoder_offset",), ("encoder_offset",), note="0.03 rad at most"),
    Family("torque_sensor_gain", ("gain",), ("torque_sensor_gain",), note="gain error 0.3 at most"),
    # effects outside today's library ("unseen")
    Family("ripple_other_order", ("ripple",), ("position_ripple",), in_library=False,
           options={"ripple": {"orders": (3, 11)}},
           note="a ripple of 3 or 11 periods per radian: discover's ripple has 6; set in_library when it "
                "searches the order"),
    Family("link_errors", ("links",), ("rigid_bodies",), in_library=False, stand_ins=("payload",),
           note="every link's mass, CoM and inertia off the nominal ones (up to 30 %, 3 cm): the answer is "
                "the nominal rigid bodies (a 'rigid_bodies' candidate); a payload stands in for the last "
                "link's share"),
    Family("warm_up", ("warm_viscous",), ("viscous_friction",), in_library=False, drift=("viscous_friction",),
           note="viscous friction 1.5-2.5 times higher at the start of each recording, decaying in 8-20 s: "
                "the answer is viscous friction, reported drifting"),
)}

#: the single families a pair is drawn from (two distinct ones; not coulomb with the Stribeck
#: family, which already holds Coulomb friction)
PAIR_MEMBERS = tuple(name for name, f in FAMILIES.items() if f.in_library and f.laws)
#: the families in the order trials are assigned to them (trial i: CYCLE[i % len(CYCLE)]);
#: "pair" three times, so that pairs are about a sixth of the trials
CYCLE = tuple(FAMILIES) + ("pair", "pair", "pair")

#: which candidate a law's coefficients belong to
LAW_CANDIDATE = {"viscous": "viscous_friction", "coulomb": "coulomb_friction", "offset": "torque_offset",
                 "armature": "armature", "stribeck": "stribeck_friction", "ripple": "position_ripple",
                 "load": "load_dependent_friction", "warm_viscous": "viscous_friction", "payload": "payload",
                 "tilt": "base_tilt", "links": "rigid_bodies", "elastic": "motor_side_elasticity",
                 "encoder_offset": "encoder_offset", "gain": "torque_sensor_gain"}


def pair(first: str, second: str) -> Family:
    """The family of two single families hidden together."""
    a, b = FAMILIES[first], FAMILIES[second]
    return Family(f"pair:{first}+{second}", a.laws + b.laws, tuple(dict.fromkeys(a.answer + b.answer)),
                  a.in_library and b.in_library, options={**a.options, **b.options})


def family_of(name: str) -> Family:
    """A family by name, ``pair:a+b`` included."""
    if name.startswith("pair:"):
        return pair(*name[5:].split("+"))
    return FAMILIES[name]


def scoring(family: Family, known) -> str:
    """``"exact"`` when discover can name the answer and its library holds the law, else ``"unseen"``."""
    return "exact" if family.in_library and set(family.answer) <= set(known) else "unseen"


def score_names(family: Family, named, known, drift=None) -> dict:
    """The named set against the family's answer (module docstring's rules): ``scoring``,
    ``exact`` (for an unseen family: no spurious name; the verdict is judged in
    :func:`score_trial`), ``spurious``, ``missed``.  ``drift``: the effects discover reports
    drifting, None when it reports none at all (a discover without the report)."""
    rule = scoring(family, known)
    named = set(named)
    if rule == "exact":
        spurious = sorted(named - set(family.answer))
        exact = named == set(family.answer) and (drift is None or set(drift) == set(family.drift))
    else:
        spurious = sorted(named - set(family.answer) - set(family.stand_ins))
        exact = not spurious
    return {"scoring": rule, "exact": exact, "spurious": spurious, "missed": sorted(set(family.answer) - named)}


def fitted_value(doc: dict, name: str):
    """The final fit's value of coefficient ``name`` in a discovery.json, or None (the final joint
    fit's table first, under the names discover's versions give it, then the not-determined
    ones' fitted values, then the last step that fitted it)."""
    for key in ("coefficients", "fitted_values", "values", "model_yaml_values"):
        if isinstance(doc.get(key), dict) and name in doc[key] and doc[key][name] is not None:
            return float(doc[key][name])
    entry = (doc.get("not_determined") or {}).get(name)
    if isinstance(entry, dict) and entry.get("fitted") is not None:
        return float(entry["fitted"])
    for step in reversed(doc.get("steps") or []):
        p = (step.get("parameters") or {}).get(name)
        if p is not None:
            return float(p["value"] if isinstance(p, dict) else p)
    return None


def coefficient_errors(truth: dict, sizes: dict, doc: dict, named, nominal_gravity) -> list[dict]:
    """Relative errors of the significant coefficients of every correctly named law (module
    docstring); ``sizes``: per law, the per-joint sizes (floors) or the law's size."""
    from .truth_simulator import JOINT_VECTORS, tilted_gravity_vector
    out = []
    for law, params in truth.items():
        if LAW_CANDIDATE[law] not in named:
            continue
        if law in JOINT_VECTORS:
            keys = JOINT_VECTORS[law]
            for i, size in enumerate(sizes[law]):
                if size < SIGNIFICANT:
                    continue
                true = np.array([params[k][i] for k in keys])
                got = [fitted_value(doc, f"{k}{i + 1}") for k in keys]
                fit = np.array([0.0 if g is None else g for g in got])
                rel = 1.0 if all(g is None for g in got) else float(np.linalg.norm(fit - true) / np.linalg.norm(true))
                out.append({"law": law, "name": "".join(keys) + str(i + 1), "true": true.tolist(),
                            "fitted": None if all(g is None for g in got) else fit.tolist(), "rel_error": rel,
                            "size": size})
        elif law == "payload" and sizes[law] >= SIGNIFICANT:
            got = doc.get("payload_mass")
            rel = 1.0 if got is None else abs(float(got) - params["mass"]) / params["mass"]
            out.append({"law": law, "name": "payload_mass", "true": params["mass"], "fitted": got,
                        "rel_error": rel, "size": sizes[law]})
        elif law == "tilt" and sizes[law] >= SIGNIFICANT:
            got = doc.get("gravity")
            g_true = tilted_gravity_vector(nominal_gravity, params)
            change = np.linalg.norm(g_true - np.asarray(nominal_gravity))
            rel = 1.0 if got is None else float(np.linalg.norm(np.asarray(got, float) - g_true) / change)
            out.append({"law": law, "name": "gravity", "true": g_true.tolist(), "fitted": got, "rel_error": rel,
                        "size": sizes[law]})
    return out


def score_trial(family: Family, truth: dict, sizes: dict, doc: dict, floor: float, known,
                nominal_gravity) -> dict:
    """Everything scored of one trial from its discovery.json ``doc``."""
    named = list(doc.get("effects") or [])
    drift = doc.get("drift")
    names = score_names(family, named, known, None if drift is None else list(drift))
    after = np.array([np.nan if v is None else v for v in
                      (doc.get("rms_after_all_fitted") or doc.get("rms_after"))], float)
    before = np.array([np.nan if v is None else v for v in doc["rms_before"]], float)
    at_floor = bool(np.all(after <= EXPLAINED_FACTOR * floor))
    truth_explained = names["exact"] and at_floor
    said = bool(doc.get("explained"))
    correct = names["exact"] if names["scoring"] == "exact" else names["exact"] and said == truth_explained
    return {**names, "correct": correct, "named": named, "explained": said, "truth_explained": truth_explained,
            "verdict_ok": said == truth_explained, "at_floor": at_floor,
            "rms_before_floors": (before / floor).tolist(), "rms_after_floors": (after / floor).tolist(),
            "noise_floor_ratio": float(np.median(np.asarray(doc["noise_floor"]["per_joint"], float)) / floor)
            if isinstance(doc.get("noise_floor"), dict) else None,
            "indistinguishable": [g.get("candidates", g) if isinstance(g, dict) else g
                                  for g in doc.get("indistinguishable") or []],
            "drift": None if drift is None else sorted(drift),
            "coefficients": coefficient_errors(truth, sizes, doc, set(named), nominal_gravity)}
