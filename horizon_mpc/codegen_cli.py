"""``python -m horizon_mpc.codegen_cli {info,prune,clear}``: the command line of the
compiled-code cache of :mod:`horizon_mpc.codegen` (its size, bounding it now, emptying it).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time

from horizon_mpc import codegen

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """``python -m horizon_mpc.codegen_cli {info,prune,clear} [--dir D] [--max-mb N]``: the
    compiled-code cache's size, bounding it now, emptying it."""
    parser = argparse.ArgumentParser(prog="python -m horizon_mpc.codegen_cli",
                                     description=main.__doc__.split(":", 1)[1].strip())
    parser.add_argument("command", choices=("info", "prune", "clear"))
    parser.add_argument("--dir", default=None, help="cache folder (default: "
                        f"{codegen.default_cache_dir()})")
    parser.add_argument("--max-mb", type=float, default=None,
                        help="prune: the bound in MB, > 0 (default $HORIZON_MPC_CACHE_MAX_MB "
                        f"or {codegen.DEFAULT_CACHE_MAX_MB:g}); `clear` empties the cache")
    args = parser.parse_args(argv)
    if args.max_mb is not None and args.command != "prune":
        parser.error(f"--max-mb is the bound of `prune`; `{args.command}` takes none")
    if args.dir is not None and not os.path.isdir(args.dir):
        parser.error(f"--dir {args.dir}: "
                     + ("not a folder" if os.path.exists(args.dir) else "no such folder"))
    default = codegen.default_cache_dir()
    if args.dir is None and default.exists() and not default.is_dir():
        parser.error(f"the cache {default} (HORIZON_MPC_CACHE_DIR, XDG_CACHE_HOME or ~/.cache) "
                     "is not a folder: the functions run uncompiled")
    if args.max_mb is not None and not (0 < args.max_mb < math.inf):
        parser.error(f"--max-mb must be a number of MB > 0, got {args.max_mb:g} (`clear` "
                     "empties the cache; HORIZON_MPC_CACHE_MAX_MB=0 leaves it unbounded)")
    bound = None
    failed: list[str] = []
    try:
        if args.command == "clear":
            removed = codegen.prune_cache(args.dir, max_bytes=0, spare_s=0.0,
                                          undeletable=failed)
        elif args.command == "prune":
            bound = codegen.cache_max_bytes() if args.max_mb is None else int(args.max_mb * 1e6)
            removed = codegen.prune_cache(args.dir, max_bytes=bound, undeletable=failed)
        info = codegen.cache_info(args.dir)
    except ValueError as exc:
        parser.error(str(exc))
    except OSError as exc:  # a cache folder that cannot be read
        parser.exit(1, f"{parser.prog}: error: {exc.filename or args.dir}: "
                       f"{exc.strerror or exc}\n")
    if args.command != "info":
        print(f"removed {len(removed)} libraries")
    when = (time.strftime("%Y-%m-%d %H:%M", time.localtime(info.oldest))
            if info.oldest is not None else "-")
    builds = (f"; {info.builds} unfinished build folders, {info.build_bytes / 1e6:.1f} MB (a "
              "build running, or one a killed process left)" if info.builds else "")
    print(f"{info.folder}: {info.libraries} libraries, {info.bytes / 1e6:.1f} MB "
          f"(least recently used {when})" + builds
          + ("" if info.folder.is_dir() else "; no such folder yet (made at the first build)"))
    if failed:
        print(f"{len(failed)} libraries could not be removed: {'; '.join(failed[:3])}",
              file=sys.stderr)
        return 1
    if args.command == "prune" and bound is None:
        print("no bound (HORIZON_MPC_CACHE_MAX_MB=0): nothing to prune")
    elif args.command == "prune" and info.bytes > bound:
        print(f"still above the bound of {bound / 1e6:g} MB: {info.recent} libraries used in the "
              f"last {codegen.PRUNE_SPARE_S / 60:g} minutes are spared (another process may be "
              "loading them)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
