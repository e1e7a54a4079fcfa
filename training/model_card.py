"""The model card: ``model_card.json`` (machine-readable) and ``MODEL_CARD.md`` (for people).

Written by :mod:`training.pipeline` from what it measured; nothing here runs a model.
"""
from __future__ import annotations

import hashlib
import json
import math
import numbers
import os
import platform
import sys
import threading
from pathlib import Path
from typing import Any, Mapping


def sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        while block := fh.read(chunk):
            h.update(block)
    return h.hexdigest()


def graph_sha256(path: str | Path) -> str:
    """The sha256 of the ONNX graph at ``path`` with its weights id and the fp32 file's sha256 (an int8 file's) left
    out of the metadata: what the graph computes. The early prior's keypoint graph and the finished export's are
    the same frozen encoder, but each export stamps the id of the whole model it came from
    (``training.export.export.weights_id``), and the int8 file the sha256 of its fp32 file, which holds that id, so
    their file hashes differ while their joints do not."""
    import onnx  # noqa: PLC0415 (the card itself needs no onnx)
    from google.protobuf.message import DecodeError  # noqa: PLC0415

    from ghnerf_runtime.contract import FP32_SHA256_KEY, WEIGHTS_ID_KEY  # noqa: PLC0415

    try:
        m = onnx.load(str(path))
    except (DecodeError, ValueError):  # not a graph: its bytes are all there is to compare
        return sha256(path)
    kept = [p for p in m.metadata_props if p.key not in (WEIGHTS_ID_KEY, FP32_SHA256_KEY)]
    del m.metadata_props[:]
    m.metadata_props.extend(kept)
    return hashlib.sha256(m.SerializeToString(deterministic=True)).hexdigest()


def write_atomic(path: str | Path, data: str | bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same folder and ``os.replace``: a crash leaves
    the old file or the new one, never half of one (the pipeline's stamps and cards are read back as JSON)."""
    path = Path(path)
    # not tempfile.mkstemp: its 0600 mode would follow the file into place; pid and thread: lanes write at once
    tmp = path.with_name(f".{path.name}.{os.getpid()}-{threading.get_ident()}.tmp")
    try:
        with open(tmp, "wb") as fh:
            fh.write(data.encode() if isinstance(data, str) else data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path


def hardware() -> dict[str, Any]:
    """CPU model, core count, memory, GPU (if torch sees one), library versions."""
    cpu = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem_gb = None
    try:
        mem_gb = round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2 ** 30, 1)
    except (ValueError, OSError, AttributeError):
        pass
    out: dict[str, Any] = {"cpu": cpu, "cores": os.cpu_count(), "memory_gb": mem_gb,
                           "platform": platform.platform(), "python": sys.version.split()[0]}
    try:
        import torch

        out["torch"] = torch.__version__
        out["gpu"] = torch.cuda.get_device_name(0) if torch.cuda.is_available() else None
    except ImportError:
        pass
    try:
        import onnxruntime

        out["onnxruntime"] = onnxruntime.__version__
    except ImportError:
        pass
    return out


def _fmt(v: Any, digits: int = 3) -> str:
    if isinstance(v, numbers.Real) and not isinstance(v, numbers.Integral):
        v = float(v)  # a numpy float32 is no float: its NaN printed as "nan", 0.5 as "0.5"
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    if isinstance(v, float):
        return f"{v:.{digits}f}" if abs(v) >= 1e-3 or v == 0 else f"{v:.2e}"
    return str(v)


def strict_json(report: Any, indent: int | None = 1) -> str:
    """``report`` as strict JSON (NaN and infinity as ``null``): :func:`ghnerf_runtime.metrics.strict_json`, the
    one writer the bench and the benchmarks use too, imported when called (the card's module loads without cv2)."""
    from ghnerf_runtime.metrics import strict_json as written

    return written(report, indent)


def write_card(out_dir: str | Path, card: Mapping[str, Any]) -> tuple[Path, Path]:
    """Write ``model_card.json`` (strict JSON: :func:`strict_json`) and ``MODEL_CARD.md`` into ``out_dir``;
    returns both paths."""
    out_dir = Path(out_dir)
    jpath = write_atomic(out_dir / "model_card.json", strict_json(card))
    mpath = write_atomic(out_dir / "MODEL_CARD.md", render_markdown(card))
    return jpath, mpath


#: Heatmap sources of the metrics, as the card names them, and their metric-key prefixes.
_HEATMAP_PREFIXES = (("rendered", ""), ("encoder", "encoder_heatmaps_"),
                     ("encoder, flip test", "encoder_heatmaps_flip_"))


def _gated(m: Mapping[str, Any], prefix: str) -> str:
    """``"<mean> / <median> (<share kept> %)"`` of the gated MPJPE, ``n/a`` when the metrics predate it."""
    return _mean_median_share(m.get(f"{prefix}mpjpe_gated_mm"), m.get(f"{prefix}mpjpe_gated_median_mm"),
                              m.get(f"{prefix}mpjpe_gated_found"))


def _mean_median_share(mean: Any, median: Any, found: Any) -> str:
    """``"<mean> / <median> (<share> %)"`` (mm, one decimal; no median where there is none), ``n/a`` without a
    mean or a share."""
    if mean is None or found is None:
        return "n/a"
    return f"{_fmt(mean, 1)}{'' if median is None else ' / ' + _fmt(median, 1)} ({100 * found:.0f} %)"


def _plain(m: Mapping[str, Any], prefix: str) -> str:
    """``"<mean> (<share> %)"`` of the plain MPJPE: the share of the joints with truth it covers (those decoded
    in both views; without it an MPJPE over 72 % of the joints reads as one over all); the mean alone when
    the metrics predate the share."""
    mm, found = m.get(f"{prefix}mpjpe_mm"), m.get(f"{prefix}mpjpe_found")
    return _fmt(mm, 1) if mm is None or found is None else f"{_fmt(mm, 1)} ({100 * found:.0f} %)"


def _prior_cells(m: Mapping[str, Any]) -> str:
    """`` <mean> / <median> | <gated mean> (<share> % within <gate> m) |`` of the skeleton prior, else n/a."""
    mm = m.get("skeleton_prior_mpjpe_mm")
    if mm is None:
        return " n/a | n/a |"
    found, gate = m.get("skeleton_prior_gated_found"), m.get("skeleton_prior_gate_m")
    share = "" if found is None else f" ({100 * found:.0f} %{'' if gate is None else f' within {gate:g} m'})"
    return (f" {_fmt(mm, 1)} / {_fmt(m.get('skeleton_prior_mpjpe_median_mm'), 1)} | "
            f"{_fmt(m.get('skeleton_prior_gated_mpjpe_mm'), 1)}{share} |")


def _quantizer(calibration: Mapping[str, Any]) -> str:
    """Which quantizer made the variant's int8 graphs (``training.export.quantize.QUANTIZER_VERSION``), where the card
    records it: the first one quantized the colour head's second call (docs/model.md). A mix (``{graph: version}``)
    names each graph's."""
    version = calibration.get("quantizer_version")
    if isinstance(version, Mapping):
        return " by quantizer versions " + ", ".join(f"{v} (`{g}`)" for g, v in version.items())
    return "" if version is None else f" by quantizer version {version}"


def _breakdown(card: dict, key: str) -> list[tuple[str, str, object]]:
    """``(model label, heatmap source, scores)`` of every ``<prefix><key>`` the metrics hold
    (``key``: ``pck@0.2_by_view``, ``pck@0.2_by_part``, ``mpjpe_by_visibility``)."""
    return [(label, src, m[f"{prefix}{key}"]) for label, m in (card.get("metrics") or {}).items()
            for src, prefix in _HEATMAP_PREFIXES if m.get(f"{prefix}{key}")]


#: The encoder table's gated-triangulation columns, by whether their 2D joints were flip-tested: (metric prefix, title).
_ENCODER_GATED_COLUMNS = {True: ("encoder_heatmaps_flip_", "MPJPE mm, flip test, gated"),
                          False: ("encoder_heatmaps_", "MPJPE mm, gated")}


def _other_run_of_the_triangulation(card: Mapping[str, Any], variant: str, prior: Mapping[str, Any]) -> str:
    """Where the encoder table scored the prior's input joints (the row of the prior's encoder precision, the
    column of its flip test) with the same gated triangulation to other digits: a clause naming that cell, so a
    reader of two figures for one calculation knows which run wrote each; empty where they agree or there is none.
    The prior's run (``training.skeleton_prior``) and the evaluation's (``ghnerf-eval``) run the same code on the
    same joints, but int8 figures move in their last digits between hosts and code versions."""
    precision = "int8" if ".int8." in str(prior.get("encoder_file") or "") else "fp32"
    label = f"{variant}_{precision}"
    prefix, column = _ENCODER_GATED_COLUMNS[bool(prior.get("flip_test", True))]
    table_cell = _gated((card.get("metrics") or {}).get(label) or {}, prefix)
    tri = (prior.get("metrics") or {}).get("triangulation_gated") or {}
    own_cell = _mean_median_share(tri.get("mean_mm"), tri.get("median_mm"), tri.get("found"))
    if "n/a" in (table_cell, own_cell) or table_cell == own_cell:
        return ""
    return (f" (the encoder table's `{label}` row, `{column}`, has {table_cell} from the evaluation's run of the "
            "same triangulation on the same joints; int8 figures move in their last digit between hosts and code "
            "versions)")


def _prior_time(prior: Mapping[str, Any]) -> str:
    """The prior run's wall time as its report splits it: training, after collecting the encoder's 2D joints of its
    training and held-out scenes (``collect_s``: a third of the shipped prior's run, which the bare training time
    left out)."""
    train = f"trained in {prior.get('train_s')} s"
    return train if prior.get("collect_s") is None else f"{train} after {prior['collect_s']} s collecting its 2D joints"


def _networks(n: int) -> str:
    return "one network" if n == 1 else f"the mean of {n} networks"


def _prior_lines(card: Mapping[str, Any]) -> list[str]:
    """The skeleton prior's held-out MPJPE (``training.skeleton_prior``), gated by its expected error."""
    L: list[str] = []
    for variant, p in (card.get("skeleton_prior") or {}).items():
        if not p or not p.get("metrics"):
            continue
        m = p["metrics"]
        tri = m.get("triangulation_gated") or {}
        L.append(f"### Skeleton prior (`{variant}/skeleton_prior.onnx`)")
        L.append("")
        L.append(f"The encoder's flip-tested int8 2D joints of {p.get('scenes')} held-out scenes "
                 f"({p.get('split')}), through the learnt skeleton prior ({_networks(p['config'].get('members', 1))} "
                 f"of {p['config'].get('steps')} steps on "
                 f"{p.get('train_scenes')} training scenes"
                 + (f" and {p['tilted_scenes']} copies of them with the {p['config'].get('tilt_mode')} turned to any "
                    f"angle (`--tilt-share {p['config'].get('tilt_share'):g}`)" if p.get("tilted_scenes") else "")
                 + f", {_prior_time(p)}), against the runtime's gated "
                 f"triangulation of the same joints, scored in the prior's own run: {_fmt(tri.get('mean_mm'), 1)} mean / "
                 f"{_fmt(tri.get('median_mm'), 1)} median mm over {100 * (tri.get('found') or 0):.0f} % of the joints"
                 + _other_run_of_the_triangulation(card, variant, p) + ". "
                 "The prior answers for every joint, with its flip test (the runtime's default); its expected "
                 "error gates them (the runtime's `joints3d.max_prior_error_m`)"
                 + (f"; without the flip test {_fmt(m['all_without_flip_test'].get('mean_mm'), 1)} mm over every "
                    "joint" if m.get("all_without_flip_test") else "")
                 + ". MPJPE mm, mean / median (share of the true joints kept)"
                 + (f"; trained beside {p['trained_beside']}" if p.get("trained_beside") else "")
                 + (f"; made by `{p['command']}`:" if p.get("command") else ":"))
        L.append("")
        L.append("| expected error at most | mean | median | p90 | joints kept |")
        L.append("|---|---|---|---|---|")
        for gate, g in (m.get("gated") or {}).items():
            L.append(f"| {gate if gate == 'inf' else gate + ' m'} | {_fmt(g.get('mean_mm'), 1)} | "
                     f"{_fmt(g.get('median_mm'), 1)} | {_fmt(g.get('p90_mm'), 1)} | "
                     f"{100 * (g.get('found') or 0):.0f} % |")
        L.append("")
    return L


def _painter_lines(card: Mapping[str, Any]) -> list[str]:
    """The novel-view painter's held-out masked PSNR (``training.learnt_fill export``)."""
    L: list[str] = []
    for variant, p in (card.get("novel_painter") or {}).items():
        if not p or not p.get("held_out"):
            continue
        rows = p["held_out"]
        L.append(f"### Novel-view painter (`{variant}/novel_painter.onnx`)")
        L.append("")
        L.append(f"A U-Net of {p.get('steps')} steps ({p.get('train_views')} training views, {p.get('train_s')} s on "
                 f"{p.get('hardware')}) that repaints the rendered picture over the body proxy of the device's joints "
                 "(`ghnerf_runtime.novel_painter`); masked PSNR dB of `ghnerf-eval`'s held-out novel views, the model's "
                 "picture (`shown`) and the painter's"
                 + (f"; made by `{p['command']}`:" if p.get("command") else ":"))
        L.append("")
        onnx_rows = p.get("onnx_held_out") or {}
        precisions = [k for k in ("fp32", "int8") if k in onnx_rows]
        L.append("| views | n | shown | painter (torch) | " + " | ".join(f"onnxruntime {k}" for k in precisions) + " |")
        L.append("|---|---|---|---|" + "---|" * len(precisions))
        for label, r in rows.items():
            L.append(f"| {label} | {r.get('n')} | {_fmt(r.get('shown'))} | {_fmt(r.get('fill:learnt'))} | "
                     + " | ".join(_fmt((onnx_rows[k].get(label) or {}).get("fill:learnt")) for k in precisions) + " |")
        L.append("")
    return L


class CardError(ValueError):
    """A model card folder that cannot record a file (no card there, or the file outside its folder)."""


def check_card_dir(card_dir: str | Path, out: str | Path, flag: str) -> None:
    """Before the work whose file the card in ``card_dir`` will record: the card is there and ``out`` lies in
    its folder (the card lists files by their path inside it).

    Raises:
        CardError: naming ``flag``, the folder and the file.
    """
    card_dir = Path(card_dir)
    if not (card_dir / "model_card.json").is_file():
        raise CardError(f"{flag} {card_dir}: no model_card.json there (`make model` writes one)")
    try:
        Path(out).resolve().relative_to(card_dir.resolve())
    except ValueError:
        raise CardError(f"{flag} {card_dir}: the output {out} is not inside that folder, so its card could not "
                        "list it") from None
    if problem := _card_problem(card_dir / "model_card.json"):
        raise CardError(f"{flag} {card_dir}: {problem}")


#: The card's sections a prior or painter is recorded in: each an object where the card has it.
_CARD_SECTIONS = ("files", "skeleton_prior", "novel_painter")


def _card_problem(path: Path) -> str | None:
    """Why the card ``path`` cannot take a record (None: it can): read before the work, as a cut or hand-edited card
    was a traceback once the prior or painter had been trained and written."""
    try:
        card = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError, RecursionError) as e:  # ValueError: not JSON, or not UTF-8
        return f"{path} cannot be read as JSON ({type(e).__name__}: {e}); `make model` writes it whole"
    if not isinstance(card, dict):
        return f"{path} holds a JSON {type(card).__name__}, not a model card object"
    wrong = next((k for k in _CARD_SECTIONS if k in card and not isinstance(card[k], dict)), None)
    if wrong is not None:
        return f"{path}: {wrong!r} is a JSON {type(card[wrong]).__name__}, not an object"
    try:  # the record is written with MODEL_CARD.md made from the whole card: an entry it cannot read fails there
        render_markdown(card)
    except (AttributeError, TypeError, KeyError, ValueError, IndexError) as e:
        return f"{path}: MODEL_CARD.md cannot be made from it ({type(e).__name__}: {e}); `make model` writes it whole"
    return None


def add_painter_to_card(card_dir: str | Path, out: Path, more: list[Path] = (), removed: list[Path] = ()) -> Path:
    """Record the painter ``out`` (its ``.json`` figures; size and hash of it and of ``more``, its int8 file)
    in the model card of ``card_dir``, and no longer the files ``removed`` (the previous painter's int8 file)."""
    card_dir = Path(card_dir)
    card = json.loads((card_dir / "model_card.json").read_text())
    card.setdefault("novel_painter", {})[out.parent.name] = json.loads(out.with_suffix(".json").read_text())
    for path in removed:
        card.get("files", {}).pop(str(path.resolve().relative_to(card_dir.resolve())), None)
    for path in (out, *more):
        card.setdefault("files", {})[str(path.resolve().relative_to(card_dir.resolve()))] = {
            "bytes": path.stat().st_size, "sha256": sha256(path)}
    write_card(card_dir, card)
    return card_dir / "model_card.json"


def render_markdown(card: Mapping[str, Any]) -> str:
    L: list[str] = []
    L.append(f"# Model card: {card.get('name', 'GHNeRF edge128')}")
    L.append("")
    L.append(card.get("summary", ""))
    L.append("")
    if card.get("quick"):
        L.append("**Smoke-test build (`--quick`): tiny data and a few iterations; the numbers mean nothing.**")
        L.append("")
    L.append("## How it was made")
    L.append("")
    L.append(f"- Command: `{card.get('command', '')}`")
    if card.get("recipe"):
        L.append(f"- Recipe: `{card['recipe']}` (`training.pipeline.RECIPES`; `make model` on another machine may "
                 "pick the other one: docs/training.md)")
    L.append(f"- Created: {card.get('created', '')}")
    hw = card.get("hardware", {})
    L.append("- Hardware (this run of the pipeline; the training table says where each model trained): "
             f"{hw.get('cpu')} ({hw.get('cores')} cores, {hw.get('memory_gb')} GB), "
             f"GPU: {hw.get('gpu') or 'none'}; torch {hw.get('torch')}, onnxruntime {hw.get('onnxruntime')}")
    wall = card.get("wall_time_s", {})
    if wall:
        total = sum(v for v in wall.values() if isinstance(v, (int, float)))
        L.append(f"- Wall time: {total / 60:.1f} min summed over the stages (runs that shared the machine overlap) (" +
                 ", ".join(f"{k} {v / 60:.1f} min" for k, v in wall.items() if isinstance(v, (int, float))) + ")")
    L.append("")
    data = card.get("data", {})
    L.append("## Data")
    L.append("")
    L.append(f"- Dataset: `{data.get('path')}` ({data.get('source')}, {data.get('resolution')} px crops); "
             f"splits: " + ", ".join(f"{k} {v}" for k, v in (data.get("splits") or {}).items()))
    if data.get("motions"):
        L.append("- Motions: " + "; ".join(f"{k}: {v}" for k, v in data["motions"].items() if v))
    L.append(f"- Metrics on the held-out split `{data.get('eval_split')}` (unseen bodies, motions and rigs), "
             f"{data.get('eval_scenes')} scenes.")
    L.append("")
    L.append("## Training")
    L.append("")
    L.append("| model | preset | iterations | rays (or images) per step | lr schedule | where (threads) | wall time |")
    L.append("|---|---|---|---|---|---|---|")
    for name, t in (card.get("training") or {}).items():
        c = t.get("config", {})
        rays = c.get("targets_per_iter", 0) * (c.get("heat_rays", 0) + c.get("patch_size", 0) ** 2)
        if t.get("images_per_step"):  # the human encoder's 2D pretraining: images, not rays
            rays = f"{t['images_per_step']} images, 2D heatmaps only"
        sched = f"Adam {c.get('lr')} x{c.get('lr_decay_gamma')} every {c.get('lr_decay_every')}"
        threads = t.get("threads") or c.get("threads") or "all"
        if t.get("segments"):  # a resumed run: each invocation's threads and steps
            threads = ", then ".join(f"{g['threads']} ({g['steps']} steps)" for g in t["segments"])
        if str(t.get("device", "")).startswith("cuda"):  # trained elsewhere than the card's hardware line
            threads = str(t.get("gpu") or t["device"])
        elif t.get("device"):
            threads = f"CPU ({threads})"
        if t.get("precision") not in (None, "fp32"):  # the pretraining's forward pass (PretrainConfig.precision):
            threads = f"{threads}, {t['precision']}"  # bf16, or each trunk scale's when the probe picked both
        L.append(f"| {name} | {c.get('preset')} | {t.get('steps')} | {rays} | {sched} | {threads} | "
                 f"{_fmt((t.get('wall_s') or 0) / 60, 1)} min |")
    L.append("")
    L.append("## Metrics (held-out split)")
    L.append("")
    # the reference length as metrics.pck takes it: the fallback sets the threshold of many synthetic views
    L.append("PCK@0.2 of the neck--mid-hip distance (the diagonal of the torso joints' box where the neck or the "
             "mid-hip is hidden) in each source view (2D joints decoded from the rendered "
             "heatmaps), MPJPE of the triangulated joints (mm, rig frame; share of the joints with truth it covers, "
             "those decoded in both views, in brackets), masked PSNR (dB) / SSIM of the novel views, "
             "heatmap MSE in the source views. Definitions: `ghnerf_runtime/metrics.py`, `training/evaluate.py`.")
    L.append("")
    L.append("MPJPE gated: the runtime's triangulation (`joints3d.triangulate_joints`: reprojection gate, "
             "minimum view confidence) on the same crops, mean / median over the joints it keeps (share kept in "
             "brackets); the mean carries a tail of joints placed wrong in both views alike.")
    L.append("")
    L.append("| model | runtime | PCK@0.2 | MPJPE mm | MPJPE mm, gated | PSNR | SSIM | heatmap MSE "
             "| undecoded joints |")
    L.append("|---|---|---|---|---|---|---|---|---|")
    for label, m in (card.get("metrics") or {}).items():
        L.append(f"| {label} | {m.get('kind')} | {_fmt(m.get('pck@0.2'))} | {_plain(m, '')} | "
                 f"{_gated(m, '')} | "
                 f"{_fmt(m.get('psnr_masked'), 2)} | {_fmt(m.get('ssim_masked'))} | {_fmt(m.get('heatmap_mse'))} | "
                 f"{m.get('pck_undecoded')}/{m.get('pck_evaluated_joints')} |")
    L.append("")
    enc = {k: m for k, m in (card.get("metrics") or {}).items() if m.get("encoder_heatmaps_pck@0.2") is not None}
    if enc:
        L.append("The human encoder's own 2D heatmaps (the encoder graph's `encoder_heatmaps` output, no "
                 "rendering; the runtime's `heatmaps.source = \"encoder\"`), decoded and triangulated the same way; "
                 "flip test: averaged with the heatmaps of the mirrored source images (the runtime's "
                 "`heatmaps.flip_test`, a second encoder run):")
        L.append("")
        with_prior = any(m.get("skeleton_prior_mpjpe_mm") is not None for m in enc.values())
        L.append("| model | runtime | PCK@0.2 | MPJPE mm | MPJPE mm, gated | PCK@0.2, flip test | MPJPE mm, flip test "
                 "| MPJPE mm, flip test, gated |" + (" MPJPE mm, skeleton prior | MPJPE mm, skeleton prior, gated |"
                                                    if with_prior else ""))
        L.append("|---|---|---|---|---|---|---|---|" + ("---|---|" if with_prior else ""))
        for label, m in enc.items():
            L.append(f"| {label} | {m.get('kind')} | {_fmt(m.get('encoder_heatmaps_pck@0.2'))} | "
                     f"{_plain(m, 'encoder_heatmaps_')} | {_gated(m, 'encoder_heatmaps_')} | "
                     f"{_fmt(m.get('encoder_heatmaps_flip_pck@0.2'))} | "
                     f"{_plain(m, 'encoder_heatmaps_flip_')} | {_gated(m, 'encoder_heatmaps_flip_')} |"
                     + (_prior_cells(m) if with_prior else ""))
        L.append("")
        if with_prior:
            L.append("MPJPE, skeleton prior: the model folder's skeleton prior (the runtime's 3D path) on the "
                     "flip-tested encoder joints, with its own flip test: mean / median over every true joint; "
                     "gated: the mean over the joints whose expected error is within the runtime's default "
                     "`joints3d.max_prior_error_m` (share kept in brackets). n/a: no prior scored (the torch row "
                     "runs none).")
            L.append("")
    views = _breakdown(card, "pck@0.2_by_view")
    if views:
        L.append("PCK@0.2 in each source view (a PCK target applies to each):")
        L.append("")
        L.append("| model | heatmaps | " + " | ".join(f"view {v}" for v in range(len(views[0][2]))) + " |")
        L.append("|---|---|" + "---|" * len(views[0][2]))
        for label, src, by in views:
            L.append(f"| {label} | {src} | " + " | ".join(_fmt(v) for v in by) + " |")
        L.append("")
    parts = _breakdown(card, "pck@0.2_by_part")
    if parts:
        names = list(parts[0][2])
        L.append("PCK@0.2 per body part (`body25.BODY_PARTS`):")
        L.append("")
        L.append("| model | heatmaps | " + " | ".join(names) + " |")
        L.append("|---|---|" + "---|" * len(names))
        for label, src, by in parts:
            L.append(f"| {label} | {src} | " + " | ".join(_fmt(by.get(n)) for n in names) + " |")
        L.append("")
    vis = _breakdown(card, "mpjpe_gated_by_visibility")  # what a device reports; older metrics: ungated
    gated = bool(vis)
    vis = vis or _breakdown(card, "mpjpe_by_visibility")
    if vis:
        names = list(vis[0][2])
        L.append(f"MPJPE (mm{', gated' if gated else ''}) by how many source views see the joint (in the crop "
                 "and not hidden by the body; share of the triangulated joints in brackets). The MPJPE above pools "
                 "all three: the synthetic truth knows where hidden joints are:")
        L.append("")
        L.append("| model | heatmaps | " + " | ".join(n.replace("_", " ") for n in names) + " |")
        L.append("|---|---|" + "---|" * len(names))
        for label, src, by in vis:
            total = sum(by[n]["joints"] for n in names) or 1
            L.append(f"| {label} | {src} | " + " | ".join(
                f"{_fmt(by[n]['mpjpe_mm'], 1)} ({100 * by[n]['joints'] / total:.0f} %)" for n in names) + " |")
        L.append("")
    L.extend(_prior_lines(card))
    L.extend(_painter_lines(card))
    by_angle = [(label, m["psnr_masked_by_source_angle"]) for label, m in (card.get("metrics") or {}).items()
                if m.get("psnr_masked_by_source_angle") and m.get("novel_views")]
    if by_angle:
        bins = by_angle[0][1]
        L.append("Novel-view PSNR by the view's angle from the nearest source camera (seen from the subject's "
                 "centre; the dataset's novel cameras circle the subject, so the wide angles look at sides no "
                 "source camera sees; the device's novel view lies between its two cameras). Mean dB (views):")
        L.append("")
        L.append("| model | " + " | ".join(f"{b['range_deg'][0]:g}-{b['range_deg'][1]:g} deg" for b in bins) + " |")
        L.append("|---|" + "---|" * len(bins))
        for label, bs in by_angle:
            L.append(f"| {label} | " + " | ".join(f"{_fmt(b.get('psnr'), 2)} ({b.get('views')})" for b in bs) + " |")
        L.append("")
    par = card.get("parity") or {}
    if par:
        L.append("## int8 vs fp32 parity")
        L.append("")
        for name, p in par.items():
            pipe = p.get("pipeline", {})
            hm = pipe.get("heatmaps", {})
            L.append(f"- {name}: end to end (encoder -> volume -> render_heat, source views of a held-out scene): "
                     f"heatmap max abs diff {_fmt(hm.get('max_abs'))}, mean {_fmt(hm.get('mean_abs'))}; "
                     f"joint peak shift {_fmt(pipe.get('peak_shift_rays'))} heatmap px; "
                     f"depth mean abs diff {_fmt(pipe.get('depth_mean_abs_m'), 4)} m.")
        L.append("")
    calib = {name: c for name, c in (card.get("calibration") or {}).items() if c and c.get("scenes")}
    if calib:  # a reader of the int8 rows asks whether the held-out scenes calibrated them
        L.append("int8 calibration (static QDQ activation ranges): " + "; ".join(
            f"{name} on {c['scenes']} scenes of the `{c.get('split')}` split{_quantizer(c)}"
            for name, c in calib.items())
            + " (evenly spaced, `training.pipeline.calibration_items`), none of the held-out scenes scored above.")
        L.append("")
    files = card.get("files") or {}
    if files:
        L.append("## Files")
        L.append("")
        L.append("| file | bytes | sha256 |")
        L.append("|---|---|---|")
        for name, f in files.items():
            L.append(f"| `{name}` | {f.get('bytes')} | `{f.get('sha256')}` |")
        L.append("")
    notes = card.get("notes") or []
    if notes:
        L.append("## Limitations")
        L.append("")
        L.extend(f"- {n}" for n in notes)
        L.append("")
    return "\n".join(L)


#: The metric keys of ``ghnerf-eval`` that score the model folder's skeleton prior (the only ones a new prior moves).
PRIOR_METRIC_PREFIX = "skeleton_prior_"


class CardUpdateError(ValueError):
    """An eval report that cannot update a card: another dataset or split, or a model the card does not list."""


def _check_report_shape(report: Any, path: Path) -> None:
    """:class:`CardUpdateError` where ``report`` is not what ``ghnerf-eval --out`` writes: an object whose
    ``models`` is an object of objects (a JSON list, or another tool's report, was an AttributeError traceback)."""
    if not isinstance(report, dict):
        raise CardUpdateError(f"{path}: holds a JSON {type(report).__name__}, not a ghnerf-eval --out report object")
    models = report.get("models")
    if models is not None and not isinstance(models, dict):
        raise CardUpdateError(f"{path}: 'models' is a JSON {type(models).__name__}, not an object of models")
    wrong = next((label for label, m in (models or {}).items() if not isinstance(m, dict)), None)
    if wrong is not None:
        raise CardUpdateError(f"{path}: models[{wrong!r}] is a JSON {type(models[wrong]).__name__}, not an object "
                              "of metrics")


def update_prior_metrics(card_dir: str | Path, eval_report: str | Path) -> list[Path]:
    """Copy the ``skeleton_prior_*`` keys of a ``ghnerf-eval --out`` report into ``card_dir``'s ``metrics.json``,
    ``metrics_<variant>.json`` and ``model_card.json``, and re-render ``MODEL_CARD.md``; returns the files written.

    For a new skeleton prior beside unchanged graphs: only the prior's columns are rescored, so the card's other
    figures keep the run that measured them (a full ``ghnerf-eval`` on another host moves int8 figures slightly).

    Raises:
        CardUpdateError: the report scored another dataset or split than the card's, or a model the card lacks.
    """
    card_dir, eval_report = Path(card_dir), Path(eval_report)
    report = json.loads(eval_report.read_text())
    _check_report_shape(report, eval_report)
    if problem := _card_problem(card_dir / "model_card.json"):  # a card that is a list was a TypeError traceback
        raise CardUpdateError(problem)
    card = json.loads((card_dir / "model_card.json").read_text())
    scored, listed = (report.get("data"), report.get("split")), (card["data"]["path"], card["data"]["eval_split"])
    if scored != listed:
        raise CardUpdateError(f"{eval_report}: scored {scored[0]} ({scored[1]}), the card in {card_dir} "
                              f"{listed[0]} ({listed[1]}): rerun ghnerf-eval on the card's dataset and split")
    models = report.get("models") or {}
    unknown = sorted(set(models) - set(card["metrics"]))
    if not models or unknown:
        raise CardUpdateError(f"{eval_report}: models {unknown or '(none)'} are not in {card_dir / 'model_card.json'} "
                              f"(it lists {sorted(card['metrics'])})")
    prior_keys = {label: {k: v for k, v in m.items() if k.startswith(PRIOR_METRIC_PREFIX)} for label, m in models.items()}
    written = []
    for path in [card_dir / "metrics.json", *sorted(card_dir.glob("metrics_*.json"))]:
        if not path.is_file():
            continue
        doc = json.loads(path.read_text())
        hit = [label for label in prior_keys if label in doc.get("models", {})]
        for label in hit:
            doc["models"][label].update(prior_keys[label])
        if hit:
            written.append(write_atomic(path, strict_json(doc)))
    for label, keys in prior_keys.items():
        card["metrics"][label].update(keys)
    written.extend(write_card(card_dir, card))
    return written


__all__ = ["sha256", "hardware", "strict_json", "write_card", "render_markdown", "update_prior_metrics",
           "CardUpdateError", "PRIOR_METRIC_PREFIX"]


def main(argv: list[str] | None = None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m training.model_card",
                                 description="Rescore a model card's skeleton-prior columns from a ghnerf-eval report "
                                             "(a new prior beside unchanged graphs).")
    ap.add_argument("--card-dir", default="models", help="the folder with model_card.json (default models)")
    ap.add_argument("--prior-metrics", required=True, metavar="EVAL_JSON",
                    help="ghnerf-eval --out report of the card's dataset and split")
    args = ap.parse_args(argv)
    try:
        written = update_prior_metrics(args.card_dir, args.prior_metrics)
    except (OSError, KeyError, json.JSONDecodeError, CardUpdateError) as exc:
        print(f"python -m training.model_card: error: {exc}", file=sys.stderr)
        return 2
    for path in written:
        print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

