"""What the user must be told about the SfM result: a capture that split or left photos out, takes that did not
join, a camera path that jumps and does not come back, steps between frames their own matches refute, an import
whose poses and photos do not match. Read from the SfM stage's record (``RUN/sfm/stage.json``) by the SfM stage,
the export and the report alike.
"""

from __future__ import annotations

import re
from pathlib import Path

from curate.core.paths import RunPaths


def _trailing(name: str):
    m = re.match(r"^(.*?)(\d+)(\D*)$", Path(name).name)
    return (m.group(1), int(m.group(2)), m.group(3)) if m else None


def name_ranges(names: list[str], limit: int = 6) -> str:
    """Photo names shortened to runs of consecutive frame numbers, e.g. ``frame_0190..frame_0361 (172)``."""
    runs: list[list[str]] = []
    for n in sorted(names):
        t = _trailing(n)
        if runs and t is not None:
            u = _trailing(runs[-1][-1])
            if u is not None and u[0] == t[0] and u[2] == t[2] and t[1] - u[1] <= 2:
                runs[-1].append(n)
                continue
        runs.append([n])
    parts = [r[0] if len(r) == 1 else f"{r[0]}..{r[-1]} ({len(r)})" for r in runs]
    return ", ".join(parts[:limit]) + (f" and {len(parts) - limit} more" if len(parts) > limit else "")


def take_warning(stats: dict) -> str | None:
    """The takes (videos, the photos of a folder) of a capture of several that did not join the others:
    each named with how many of its frames are in the model curate uses; None when every take joined.
    ``stats``: the SfM stage's statistics (``takes``: :func:`curate.sfm.prep.take_counts`)."""
    from curate.sfm.config import TAKE_MIN_FRACTION
    from curate.sfm.prep import takes_not_joined
    out = takes_not_joined(stats.get("takes") or [], TAKE_MIN_FRACTION)
    if not out:
        return None
    names = ", ".join(t["take"] for t in out)
    each = "; ".join(f"take {t['take']}: {t['n_in_model']} of {t['n_frames']} "
                     f"{'frames' if t['kind'] == 'video' else 'photos'} in the model"
                     + (f" ({t['n_in_other_parts']} in a model of their own)" if t["n_in_other_parts"] else "")
                     for t in out)
    return (f"{each}: {'it shares' if len(out) == 1 else 'they share'} too little with the other takes to be "
            f"placed with them (film a stretch that overlaps another take, or curate {names} "
            f"{'on its own' if len(out) == 1 else 'each on its own'})")


def split_warning(run_dir: Path, each: bool = False) -> str | None:
    """A warning when SfM left kept photos out of the model curate uses (the capture split, or
    photos that did not register): the takes that did not join (:func:`take_warning`), the models'
    sizes and which photos are lost; None when it kept all.
    ``each`` (``--on-split each``): the other parts of >= 10 photos are curated in ``RUN/parts``."""
    from curate.core.stage import read_stage
    st = (read_stage(RunPaths(run_dir).sfm) or {}).get("stats", {})
    takes = take_warning(st)
    rest = _split_text(st, run_dir, each)
    if takes is None or rest is None:
        return takes or rest
    return f"{takes}. {rest[0].upper()}{rest[1:]}"


def _split_text(st: dict, run_dir: Path, each: bool) -> str | None:
    if each and len(sizes := st.get("model_sizes") or []) > 1:
        from curate.sfm.config import MIN_PART
        own = [n for n in sizes[1:] if n >= MIN_PART]
        if own:
            return (f"the capture split into {len(sizes)} models ({', '.join(map(str, sizes))} photos), each in "
                    f"its own frame: the largest is curated here and {len(own)} more in {Path(run_dir) / 'parts'} "
                    f"(--on-split each), each with its own report and export"
                    + (f"; {len(sizes) - 1 - len(own)} models under {MIN_PART} photos are left out"
                       if len(own) < len(sizes) - 1 else ""))
    lost = st.get("unregistered") or []
    if not lost:
        return None
    sizes = st.get("model_sizes") or []
    kept = st.get("n_kept", st.get("n_registered", 0) + len(lost))
    glob = (st.get("mappers_tried") or {}).get("global") or {}
    if st.get("mapper") == "global" and glob.get("pruned_to") is not None:
        inc = (st["mappers_tried"].get("incremental") or {}).get("model_sizes") or []
        ver = glob.get("verified") or {}
        loose = [j for j in glob.get("joins") or [] if not j.get("joined")]
        how = (f"the incremental mapper split the capture ({', '.join(map(str, inc))} photos) and the global "
               f"mapper placed {(glob.get('model_sizes') or ['?'])[0]} in one model; the photos of parts it bends"
               + (f", of parts too few points tie to the rest ({len(loose)} part{'s' * (len(loose) > 1)}, "
                  f"{sum(j['photos'] for j in loose)} photos)" if loose else "")
               + f", and those no part checks whose own pose check failed ({len(ver.get('refused') or {})} of "
               f"{ver.get('checked', 0)}), are left out")
    elif len(sizes) > 1:
        how = f"the capture split into {len(sizes)} models ({', '.join(map(str, sizes))} photos)"
    elif st.get("off_path"):
        how = "SfM placed some frames off their video's path"
    elif st.get("refuted_frames"):
        how = "SfM placed some frames where their own matches with the next frames refute them"
    else:
        how = "SfM could not register every photo"
    off = sum(len(v) for v in (st.get("off_path") or {}).values())
    refuted = sorted(n for v in (st.get("refuted_frames") or {}).values() for n in v)
    why = [f"{off} of them placed off their video's path, a stretch that jumped away and back"] if off else []
    why += [f"{len(refuted)} placed where their own matches with the next frames refute them: "
            f"{name_ranges(refuted)}"] if refuted else []
    return (f"{how}: curate uses the largest, {st.get('n_registered', kept - len(lost))} of {kept} photos; "
            f"{len(lost)} {'is' if len(lost) == 1 else 'are'} left out of the selection, the export and the evaluation"
            + (f" ({'; '.join(why)})" if why else "") + f": {name_ranges(lost)}")


def path_warning(stats: dict) -> str | None:
    """A warning for each video take whose path in the model jumps at over
    :data:`curate.sfm.continuity.FOLD_FACTOR` times the speed around the step and does not come back (a model
    folded there keeps every frame, the ones on one side wrong); None without such a jump.
    ``stats``: the SfM stage's statistics (``path_jumps``: :func:`curate.sfm.continuity.jumps_along`, of the
    model curate uses; each other part of a split capture, ``parts[k]``, may carry its own; ``takes``
    tells a take of numbered photos from a video; ``mapper``: a model of the incremental mapper gets the
    hint to map again with the global one, which kept a rendered walk down a hall and back whole where the
    incremental one folded it: docs/sfm.md)."""
    kinds = {t["take"]: t["kind"] for t in stats.get("takes") or []}          # curate.sfm.prep.take_counts
    where = [("", stats.get("path_jumps") or {})]
    where += [(f"in the other model of {p['n_registered']} photos, ", p.get("path_jumps") or {})
              for p in (stats.get("parts") or [])[1:]]
    each = []
    for prefix, jumps in where:
        for take, js in sorted(jumps.items()):
            j = max(js, key=lambda x: x["x_around"] if x["x_around"] is not None else float("inf"))
            how = f"{j['x_around']:g} times the steps around it" if j["x_around"] is not None else "an unbounded step"
            more = f"; {len(js) - 1} more such jump{'s' * (len(js) > 2)}" if len(js) > 1 else ""
            what = f"{take} (in name order)" if kinds.get(take) == "photos" else f"video {take}"
            each.append(f"{prefix}{what}: the camera path jumps from {j['from']} to {j['to']} ({how}{more}) "
                        "and does not come back")
    if not each:
        return None
    other = ("; if they are wrong, run again with --mapper global, COLMAP's global mapper, which does not grow the "
             "model photo by photo" if stats.get("mapper") == "incremental" else "")
    return ("; ".join(each) + ": SfM may have folded the model there, the cameras on one side of the jump then "
            "being wrong. Look at the cameras (the export's sparse/0 in COLMAP's GUI, or transforms.json in "
            "nerfstudio's viewer) before training on them" + other)


def step_warning(stats: dict) -> str | None:
    """A warning for each take (a video, numbered photos) of the model curate uses, and of each other part, with
    steps between consecutive frames that their own verified matches refute: under half of the matches fit the
    model's relative pose (``parts[k].unexplained_steps``: :func:`curate.sfm.continuity.unexplained_steps`, and
    ``parts[k].steps_checked``: {take: steps checked}). The
    cameras there are wrong, and where many steps are, the whole model may be (a blurred walk); None where every
    step checked fits."""
    kinds = {t["take"]: t["kind"] for t in stats.get("takes") or []}
    each = []
    for k, part in enumerate(stats.get("parts") or []):
        prefix = "" if k == 0 else f"in the other model of {part['n_registered']} photos, "
        for take, bad in sorted((part.get("unexplained_steps") or {}).items()):
            worst = min(bad, key=lambda x: x["fit"])
            what = f"{take} (in name order)" if kinds.get(take) == "photos" else f"video {take}"
            more = f" and {len(bad) - 1} more" if len(bad) > 1 else ""
            checked = (part.get("steps_checked") or {}).get(take, len(bad))
            each.append(f"{prefix}{what}: {len(bad)} of {checked} steps between "
                        f"consecutive frames are not what the frames' own matches say ({worst['from']} to "
                        f"{worst['to']} fits {worst['fit']:.0%} of their {worst['inliers']} verified matches{more})")
    if not each:
        return None
    return ("; ".join(each) + ": SfM placed the cameras there wrongly, and where many steps disagree the whole model "
            "may be wrong (blur, a fast turn). Look at the cameras (the export's sparse/0 in COLMAP's GUI, or "
            "transforms.json in nerfstudio's viewer) before training on them")


def import_warning(run_dir: Path) -> str | None:
    """A warning about an import of known poses (``curate run PHOTOS --poses POSES``): when fewer than
    half of the poses found a photo in the photo folder, or fewer than half of the folder's photos have a
    pose (:data:`curate.sfm.poses.MIN_MATCHED_FRACTION`: the folder is probably not the capture the poses
    describe), or when no 3D points could be triangulated for poses that came without them; None otherwise."""
    from curate.core.stage import read_stage
    from curate.sfm.poses import MIN_MATCHED_FRACTION
    rec = read_stage(RunPaths(run_dir).sfm) or {}
    if rec.get("mode") != "import":
        return None
    st = rec.get("stats") or {}
    out = []
    m = st.get("pose_match")
    if m:
        n, k = m["n_poses"], m["n_matched"]
        if k < MIN_MATCHED_FRACTION * n:
            out.append(f"only {k} of the {n} poses of {rec.get('source')} found a photo in {m['folder']} "
                       f"({n - k} left out, e.g. {name_ranges(m['poses_without_photo'], 3)}): is this the capture "
                       "the poses describe?")
        if m.get("n_photos") and m["n_photos"] - m["n_unposed"] < MIN_MATCHED_FRACTION * m["n_photos"]:
            out.append(f"only {m['n_photos'] - m['n_unposed']} of the {m['n_photos']} photos in {m['folder']} have a "
                       f"pose in {rec.get('source')} ({m['n_unposed']} left out, e.g. "
                       f"{name_ranges(m['photos_without_pose'], 3)}): is this the capture the poses describe?")
    tri = st.get("triangulation") or {}
    if tri.get("status") == "failed":
        out.append(f"no 3D points could be triangulated from the photos with the known poses ({tri.get('reason')}; "
                   f"see {Path(run_dir) / 'sfm' / 'colmap.log'}): the export's sparse/0 has none")
    elif tri.get("status") == "done" and tri.get("n_points", 0) == 0:
        out.append("triangulating the photos with the known poses found no 3D points "
                   f"({tri.get('n_pairs_verified', 0)} verified image pairs): the export's sparse/0 has none")
    return "; ".join(out) or None
