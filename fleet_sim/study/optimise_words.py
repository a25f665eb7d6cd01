"""The answer of a design search in a planner's words, from optimise.json alone: what
`fleet-sim optimise` prints and writes as its statement, and what its report shows first.

"The cheapest system that meets both targets (throughput at least 98 % of demand; p95 lead
time at most 600 s): 16 AGVs, opportunity charging, a fifth charger at C05: 742,000 EUR. Over
12 replications it reaches ... No cheaper design does: the same system with 15 AGVs (702,000
EUR) misses p95 lead time 631 s (604 to 658)."

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from fleet_sim.analysis.kpis import kpi_label, kpi_short, target_words
from fleet_sim.analysis.paired import number_text
from fleet_sim.config.decisions import count_path
from fleet_sim.config.experiment import Target


def money(value: float, currency: str) -> str:
    """742,000 EUR."""
    return f"{value:,.0f} {currency}"



def _unit(kpi: str) -> str:
    """The unit after a number, from the catalogue's label: ``s``, ``% of demand``."""
    _, _, unit = kpi_label(kpi).partition(" [")
    unit = unit.removesuffix("]")
    return f" {unit}" if unit and unit != "count" else ""


def target_of(row: Mapping[str, Any], bound: float | None = None) -> Target:
    value = float(row["bound"] if bound is None else bound)
    return Target(kpi=str(row["kpi"]), at_least=value) if row["at_least"] \
        else Target(kpi=str(row["kpi"]), at_most=value)


def and_words(parts: Sequence[str]) -> str:
    if not parts:
        return ""
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]


def value_words(row: Mapping[str, Any]) -> str:
    """``p95 lead time 631 s (604 to 658)``: the mean and its 95 % interval."""
    kpi = str(row["kpi"])
    if row["mean"] is None:
        return f"{kpi_short(kpi)}: no value"
    text = f"{kpi_short(kpi)} {number_text(row['mean'])}{_unit(kpi)}"
    if row["ci_low"] is not None and row["ci_high"] is not None:
        text += f" ({number_text(row['ci_low'])} to {number_text(row['ci_high'])})"
    return text


def interval_cell(row: Mapping[str, Any]) -> str:
    """A table cell: ``631 (604 to 658)``, "-" where the design was not run."""
    if row["mean"] is None:
        return "-"
    if row["ci_low"] is None or row["ci_high"] is None:
        return number_text(row["mean"])
    return (f"{number_text(row['mean'])} ({number_text(row['ci_low'])} to "
            f"{number_text(row['ci_high'])})")


def targets_words(document: Mapping[str, Any]) -> tuple[str, str]:
    """("both targets", "throughput at least 95 % of demand; p95 lead time at most 600 s")."""
    rows = document["designs"][0]["targets"] if document["designs"] else []
    count = len(rows)
    what = "every target" if count > 2 else ("both targets" if count == 2 else "the target")
    return what, "; ".join(target_words(target_of(r)) for r in rows)


def _agvs(count: int, key: str) -> str:
    kind = "" if key == "fleet.size" else key.split(".")[2] + " "
    return f"{count} {kind}{'AGV' if count == 1 else 'AGVs'}"


def _verdict_phrase(row: Mapping[str, Any]) -> str:
    """What became of a design cheaper than the answer, after its subject (singular)."""
    verdict = row["verdict"]
    if verdict == "fails":
        if row["inferred"] or not row["replications"]:
            return f"fails: {row['reason']}" if row["reason"] else "fails"
        misses = [r for r in row["targets"] if r["meets_bound"] is False]
        if misses:
            return "misses " + and_words([value_words(r) for r in misses[:2]])
        return "fails the targets within their tolerance: " + and_words(
            [value_words(r) for r in row["targets"]])
    if verdict == "ruled out":
        return f"is ruled out: {row['reason']}"
    if verdict == "refused":
        return f"does not fit its layout: {row['reason']}"
    if verdict == "undecided":
        return (f"is not decided at {row['replications']} replications: "
                + and_words([value_words(r) for r in row["targets"]]))
    return f"is {verdict}" + (f": {row['reason']}" if row["reason"] else "")


def _count_key(choices: Mapping[str, Any]) -> str | None:
    keys = [k for k in choices if count_path(k)]
    return keys[0] if len(keys) == 1 else None


def next_cheaper(document: Mapping[str, Any], answer: int) -> dict[str, Any] | None:
    """The design to name beside the answer: one AGV fewer with the same other choices where
    the space has it, else the dearest design cheaper than the answer."""
    designs: list[dict[str, Any]] = document["designs"]
    chosen = designs[answer]
    key = _count_key(chosen["choices"])
    if key is not None:
        rest = {k: v for k, v in chosen["choices"].items() if k != key}
        for d in designs:
            if d["choices"].get(key) == chosen["choices"][key] - 1 and \
                    {k: v for k, v in d["choices"].items() if k != key} == rest:
                return d
    cheaper = [d for d in by_price(designs) if _cheaper(d, chosen)]
    return cheaper[-1] if cheaper else None


def by_price(designs: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    return sorted(designs, key=lambda d: (float(d["price"]), int(d["index"])))


def _cheaper(d: Mapping[str, Any], than: Mapping[str, Any]) -> bool:
    return (float(d["price"]), int(d["index"])) < (float(than["price"]), int(than["index"]))


def verdict_counts(verdicts: Sequence[str]) -> dict[str, int]:
    counts: dict[str, int] = {}
    for v in verdicts:
        counts[v] = counts.get(v, 0) + 1
    return counts


VERDICT_VERBS = {"fails": ("fails", "fail"), "ruled out": ("is ruled out", "are ruled out"),
                 "refused": ("does not fit its layout", "do not fit their layout"),
                 "undecided": ("is undecided", "are undecided"),
                 "not examined": ("was not examined", "were not examined")}
"""A verdict of designs cheaper than the answer, as a verb: (one design, several)."""


def _others_sentence(verdicts: Sequence[str]) -> str:
    """``Of the other 5 cheaper designs, 4 fail and 1 is ruled out.``"""
    counts = verdict_counts(verdicts)

    def verb(v: str, n: int) -> str:
        one, many = VERDICT_VERBS.get(v, (f"is {v}", f"are {v}"))
        return one if n == 1 else many

    if len(verdicts) == 1:
        return f"The other cheaper design {verb(verdicts[0], 1)}."
    return (f"Of the other {len(verdicts)} cheaper designs, "
            + and_words([f"{n} {verb(v, n)}" for v, n in counts.items()]) + ".")


def answer_statements(document: Mapping[str, Any], words: Sequence[str]) -> list[str]:
    """The answer in a planner's words (see the module); `words`: each design in words."""
    currency = str(document["currency"])
    what, targets = targets_words(document)
    designs: list[dict[str, Any]] = document["designs"]
    answer = answer_index(document)
    out: list[str] = []
    if document.get("stopped"):
        out.append(f"The search stopped before it could name an answer: {document['stopped']}")
    if answer is None:
        out.append(f"No design in the space meets {what} ({targets}) with "
                   f"{100 * float(document['confidence']):g} % confidence.")
        close = document.get("closest")
        if close is not None:
            index = index_of(document, str(close["design"]))
            name = words[index] if index is not None else str(close["design"])
            row = next(r for r in close["targets"] if r["kpi"] == close["binding_target"])
            misses = close.get("misses_by_tolerances")
            by = f", {number_text(misses)} tolerances off" if misses is not None else ""
            out.append(f"The target that binds is {target_words(target_of(row))}: the design "
                       f"that comes closest, {name} ({money(close['price'], currency)}), "
                       f"reaches {value_words(row)}{by}.")
        return out
    chosen = designs[answer]
    out.append(f"The cheapest system that meets {what} ({targets}): {words[answer]}: "
               f"{money(chosen['price'], currency)}.")
    out.append(f"Over {chosen['replications']} replications it reaches "
               + and_words([value_words(r) for r in chosen["targets"]]) + ".")
    cheaper = [d for d in designs if _cheaper(d, chosen)]
    below = next_cheaper(document, answer)
    if below is None:
        out.append("It is the cheapest design in the space.")
    else:
        key = _count_key(chosen["choices"])
        if key is not None and \
                below["choices"].get(key) == chosen["choices"][key] - 1:
            subject = f"the same system with {_agvs(int(below['choices'][key]), key)}"
        else:
            subject = f"the next cheaper design, {words[int(below['index'])]}"
        price = money(below["price"], currency)
        price = f"({price})" if subject.startswith("the same") else f"({price}),"
        lead = "No cheaper design is shown to meet them" if \
            any(d["verdict"] == "undecided" for d in cheaper) else "No cheaper design does"
        text = f"{lead}: {subject} {price} {_verdict_phrase(below)}."
        others = [d["verdict"] for d in by_price(cheaper) if d is not below]
        if others:
            text += " " + _others_sentence(others)
        out.append(text)
    undecided = list(document.get("undecided_cheaper") or [])
    if undecided:
        out.append("Not decided at the replication limit, and cheaper: " + "; ".join(
            words[i] if (i := index_of(document, label)) is not None else label
            for label in undecided) + " (more replications could still tell).")
    return out


def guarantee_sentence(document: Mapping[str, Any]) -> str:
    """optimise.json's guarantee, with the KPIs in words; when no design meets, what it says
    of the space; none when the search stopped early."""
    if document.get("stopped"):
        return "The search stopped before it was done: its guarantee does not hold yet."
    tolerance: Mapping[str, float] = document["tolerance"]
    within = "; ".join(f"{kpi_short(k)} within {number_text(v)}{_unit(k)}"
                       for k, v in tolerance.items())
    chance = f"With probability at least {100 * float(document['confidence']):g} %"
    if document.get("answer") is None:
        undecided = " (the designs undecided at the replication limit excepted)" \
            if document.get("undecided_cheaper") else ""
        return (f"{chance}, no design in the space meets every target by more than its "
                f"tolerance ({within}){undecided}.")
    left = len(document.get("undecided_cheaper") or [])
    but = "" if not left else \
        (f", but for the {left} cheaper designs undecided at the replication limit"
         if left > 1 else ", but for the cheaper design undecided at the replication limit")
    return (f"{chance}, the design named meets every target (within its tolerance: {within}), "
            f"and no cheaper design meets them all by more than that tolerance{but}.")


def runs_sentence(document: Mapping[str, Any]) -> str:
    procedure = document.get("procedure") or {}
    counted = procedure.get("designs_counted", document["design_count"])
    reps = document["answer"]["replications"] if document["answer"] else \
        procedure.get("min_replications", "?")
    return (f"{document['runs_used']} runs used, against {document['full_grid_runs']} for the "
            f"full grid ({counted} designs at {reps} replications each); "
            f"{document['designs_examined']} of {document['design_count']} designs run.")


def answer_index(document: Mapping[str, Any]) -> int | None:
    answer = document.get("answer")
    return None if answer is None else index_of(document, str(answer["design"]))


def index_of(document: Mapping[str, Any], label: str) -> int | None:
    for d in document["designs"]:
        if d["label"] == label:
            return int(d["index"])
    return None
