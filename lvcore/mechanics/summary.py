"""Plain-text summaries of simulation results (the ``lvcore simulate`` report and the app's)."""
from __future__ import annotations

from lvcore.domain.outputs import DEFAULT_STRAIN_LAYER, LEVEL_NAMES, STRAIN_LAYER_LABELS, strains_by_level


def format_summary(result) -> str:
    """A readable multi-line summary of a simulation result (or of its ``to_dict()``)."""
    d = result if isinstance(result, dict) else result.to_dict()
    state = "converged" if d["converged"] else "NOT CONVERGED"
    lines = [f"solver: {state}" + (f" ({d['message']})" if d["message"] and d["message"] != state else ""),
             f"  {d['newton_iterations']} Newton iterations, {d['load_steps']} load steps, {d['dofs']} dofs, "
             f"{d['seconds']:.2f} s"]
    vol = d.get("cavity_volume_ml")
    if vol:
        lines.append(f"cavity volume: V₀ (reference, stress-free) {vol['reference']:.3f} mL"
                     + (f", EDV (loaded, LVV) {vol['loaded']:.3f} mL" if vol.get("loaded") is not None else ""))
    if d.get("lvv_standardised") is not None:  # one name for this ratio everywhere: EDV/V₀
        lines.append(f"EDV/V₀ (loaded over reference cavity volume): {d['lvv_standardised']:.4f}")
    if d.get("apex"):
        for name, pos in d["apex"].items():
            lines.append(f"{name} apex (deformed): ({pos[0]:.4f}, {pos[1]:.4f}, {pos[2]:.4f}) mm")
    for k, pos in enumerate(d.get("probes") or []):
        lines.append(f"probe {k} (deformed): ({pos[0]:.4f}, {pos[1]:.4f}, {pos[2]:.4f}) mm")
    if d.get("strains") is not None:
        layer = d.get("strain_layer") or DEFAULT_STRAIN_LAYER
        lines.append(f"circumferential Green strain E_cc, end diastole as reference, {STRAIN_LAYER_LABELS[layer]} "
                     "(rows: levels base -> apex; columns: sectors S1..S6):")
        for name, row in zip(LEVEL_NAMES, strains_by_level(d["strains"])):
            lines.append(f"  {name:>10s} " + " ".join(f"{v:+.4f}" for v in row))
    for w in d.get("warnings") or []:
        lines.append(f"WARNING: {w}")
    sens = d.get("sensitivities") if isinstance(result, dict) else getattr(result, "sensitivities", None)
    if sens:
        lines.append("sensitivities: " + ", ".join(str(k) for k in sens) + " (use --json for values)")
    return "\n".join(lines)


__all__ = ["format_summary"]
