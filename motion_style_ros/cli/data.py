"""``motion-style data``: index the motion datasets or a user's labelled BVH folder, build the cache,
check or rewrite the split.

Datasets are read from ``$MOTION_STYLE_DATASETS`` (default ``~/.cache/motion-datasets``, where
``../shared/datasets/unpack.sh`` puts them); a user's folder from its path (``--dataset PATH``, see
:mod:`motion_style_ros.io.user_data`); the cache goes to ``$MOTION_STYLE_CACHE`` (default
``~/.cache/motion_style_ros``). Skipped files are reported as one warning line each on stderr.
"""

DATASETS = ("bandai-1", "bandai-2", "cmu", "xia")


def add_parser(subparsers):
    p = subparsers.add_parser(
        "data", help="index datasets or your own BVH folder, build the cache, check the split",
        description="Index the motion datasets or a labelled BVH folder of your own, build their "
                    "cache, check or rewrite the committed train/val/test split.",
    )
    actions = p.add_subparsers(dest="action", metavar="ACTION", required=True)
    index = actions.add_parser("index", help="count clips per content, style and split",
                               description="Index a dataset and print its clip counts.")
    index.add_argument("--dataset", type=_dataset, action="append", metavar="NAME|PATH",
                       help=f"dataset to index: {', '.join(DATASETS)}, or the path of a labelled BVH "
                            "folder (its split is written beside it on first use; repeatable; "
                            "default: the four named)")
    build = actions.add_parser("cache", help="build or refresh the Bandai or a folder's cache, with timings",
                               description="Parse the Bandai sets (or a labelled BVH folder) into the "
                                           "cache where it is missing or stale, then time a load "
                                           "from the cache.")
    build.add_argument("--rebuild", action="store_true", help="parse everything again")
    build.add_argument("--dataset", type=_folder, default=None, metavar="PATH",
                       help="a labelled BVH folder instead of the Bandai sets")
    split = actions.add_parser(
        "split", help="check or regenerate the committed Bandai split",
        description="Compare the committed bandai_split.csv with the split rule applied to the "
                    "datasets (--check), or write it (--write). The rule is documented in "
                    "motion_style_ros/io/datasets.py.",
    )
    mode = split.add_mutually_exclusive_group(required=True)
    mode.add_argument("--check", action="store_true", help="exit 1 if the file differs from the rule")
    mode.add_argument("--write", action="store_true", help="rewrite the file from the rule")
    stats = actions.add_parser(
        "rotation-stats", help="check or regenerate the shipped rotation statistics",
        description="Compare the shipped rotation_stats.json (per-joint 6D local-rotation mean and "
                    "std of the Bandai dataset-2 train takes, which retargeted clips are conformed "
                    "to) with the datasets (--check), or write it (--write).",
    )
    mode = stats.add_mutually_exclusive_group(required=True)
    mode.add_argument("--check", action="store_true", help="exit 1 if the file differs")
    mode.add_argument("--write", action="store_true", help="rewrite the file from the datasets")
    p.set_defaults(func=run)


def _dataset(value: str) -> str:
    """A dataset name, or the path of an existing folder (argparse type: a bad one is one line)."""
    import argparse
    from pathlib import Path

    if value not in DATASETS and not Path(value).is_dir():
        raise argparse.ArgumentTypeError(f"{value}: not {' or '.join(DATASETS)}, nor a folder")
    return value


def _folder(value: str) -> str:
    """The path of an existing folder (argparse type)."""
    import argparse
    from pathlib import Path

    if not Path(value).is_dir():
        raise argparse.ArgumentTypeError(f"{value}: not a folder")
    return value


def run(args) -> int:
    return {"index": _index, "cache": _cache, "split": _split,
            "rotation-stats": _rotation_stats}[args.action](args)


def _rotation_stats(args) -> int:
    from motion_style_ros.io import datasets as ds
    from motion_style_ros.io.resources import rotation_stats_file

    expected, path = ds.rotation_stats_json(progress=False), rotation_stats_file()
    if args.write:
        path.write_text(expected, encoding="utf-8")
        print(f"wrote {path}")
        return 0
    if path.is_file() and path.read_text(encoding="utf-8") == expected:
        print(f"{path} matches the datasets")
        return 0
    print(f"{path} differs from the statistics of the datasets; rewrite it with "
          "'motion-style data rotation-stats --write' if the datasets really changed")
    return 1


def _index(args) -> int:
    from collections import Counter

    from motion_style_ros.io import datasets as ds

    root = ds.datasets_root() if set(args.dataset or DATASETS) & set(DATASETS) else None
    indexers = {
        "bandai-1": lambda: ds.index_bandai(root, (1,)),
        "bandai-2": lambda: ds.index_bandai(root, (2,)),
        "cmu": lambda: ds.index_cmu(root),
        "xia": lambda: ds.index_xia(root),
    }
    for i, name in enumerate(args.dataset or DATASETS):
        if name in indexers:
            infos, where = indexers[name](), root
        else:
            infos, where = _user_folder(name).infos, name
        splits = [s for s in ds.SPLITS if any(c.split == s for c in infos)]
        print(("\n" if i else "") + f"{name}: {len(infos)} clips under {where}")
        totals = Counter(c.split for c in infos)
        for field in ("content", "style"):
            counts = Counter((getattr(c, field), c.split) for c in infos)
            rows = [[v, *(counts[v, s] for s in splits), sum(counts[v, s] for s in splits)]
                    for v in sorted({v for v, _ in counts})]
            _print_table([field, *splits, "total"], rows)
        _print_table(["all clips", *splits, "total"], [["", *(totals[s] for s in splits), len(infos)]])
    return 0


def _user_folder(path: str, rebuild: bool = False):
    """A labelled folder through its cache; prints what was skipped and the styles too small to train."""
    from motion_style_ros.io import user_data

    folder = user_data.load_folder(path, rebuild=rebuild)
    print(f"{path}: {len(folder.infos)} takes usable, {len(folder.problems)} file(s) skipped; "
          f"split in {user_data.SPLIT} beside them")
    for style, n in folder.too_few().items():
        print(f"{path}: style {style!r} has {n} take(s); training needs at least {user_data.MIN_TAKES} "
              "(one each for train, val and test): add takes or leave it out with --exclude-styles")
    return folder


def _print_table(header, rows):
    widths = [max(len(str(r[k])) for r in [header, *rows]) for k in range(len(header))]
    widths[0] = max(widths[0], 20)
    for r in [header, *rows]:
        print("  ".join(str(v).ljust(w) if k == 0 else str(v).rjust(w)
                        for k, (v, w) in enumerate(zip(r, widths))).rstrip())


def _cache(args) -> int:
    import time

    from motion_style_ros.io import cache
    from motion_style_ros.io import datasets as ds

    if args.dataset:
        start = time.perf_counter()
        folder = _user_folder(args.dataset, rebuild=args.rebuild)
        state = "up to date" if folder.build_seconds is None else f"parsed in {folder.build_seconds:.1f} s"
        frames = sum(m.n_frames for m in folder.motions)
        print(f"{args.dataset}: {state} ({cache.cache_dir()}); {len(folder.motions)} takes, {frames:,} "
              f"frames at 30 fps in {time.perf_counter() - start:.2f} s")
        return 0
    for name, seconds in ds.build_cache(rebuild=args.rebuild).items():
        state = "up to date" if seconds is None else f"parsed in {seconds:.1f} s"
        print(f"{name}: {state} ({cache.cache_dir()})")
    start = time.perf_counter()
    clips = ds.load_bandai(progress=False)
    frames = sum(m.n_frames for _, m in clips)
    print(f"cached load: {len(clips)} clips, {frames:,} frames in {time.perf_counter() - start:.2f} s")
    return 0


def _split(args) -> int:
    from collections import Counter

    from motion_style_ros.io import datasets as ds

    expected = ds.split_csv()
    path = ds.split_file()
    rows = [line.split(",") for line in expected.splitlines()[1:]]
    counts = Counter((name.split("_")[0], split) for name, split in rows)
    summary = ", ".join(f"{d} {s} {n}" for (d, s), n in sorted(counts.items()))
    if args.write:
        path.write_text(expected, encoding="utf-8")
        print(f"wrote {path}: {len(rows)} clips ({summary})")
        return 0
    committed = path.read_text(encoding="utf-8") if path.is_file() else ""
    if committed == expected:
        print(f"{path} follows the split rule: {len(rows)} clips ({summary})")
        return 0
    old, new = set(committed.splitlines()), set(expected.splitlines())
    print(f"{path} differs from the split rule applied to the datasets: "
          f"{len(old - new)} row(s) only in the file, {len(new - old)} only in the rule; "
          "rewrite it with 'motion-style data split --write' if the datasets really changed")
    for line in sorted(old ^ new)[:10]:
        print(f"  {'file' if line in old else 'rule'}: {line}")
    return 1
