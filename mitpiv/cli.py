"""Command-line interface: ``mitpiv render`` and ``mitpiv info``.

Thin: parses arguments, calls library functions, shows progress. Errors from mitpiv
print as one line and exit with status 2.
"""

from __future__ import annotations

import argparse
import json
import sys

from mitpiv.errors import MitpivError


def _parse_define(items: list[str]) -> dict:
    out = {}
    for item in items or []:
        if "=" not in item:
            raise MitpivError(f"-D expects name=value, got {item!r}.")
        k, v = item.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def cmd_render(args) -> int:
    import mitpiv

    files = mitpiv.render_scene(
        args.scene, out_dir=args.out, frames=args.frames, params=_parse_define(args.define), spp=args.spp, seed=args.seed
    )
    print(f"wrote {len(files)} EXR file(s) to {args.out}")
    return 0


def cmd_info(args) -> int:
    from mitpiv.io import read_exr

    img, meta = read_exr(args.file)
    print(f"{args.file}: {img.shape[1]}x{img.shape[0]} float32, min {img.min():.6g}, max {img.max():.6g}, sum {img.sum(dtype='float64'):.6g}")
    print(json.dumps(meta, indent=2, sort_keys=True))
    return 0


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="mitpiv", description="Physically based rendering testbed for volumetric PIV.")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render every sensor of a scene XML for each frame to EXR + PNG")
    r.add_argument("scene", help="scene XML file")
    r.add_argument("--out", required=True, help="output folder")
    r.add_argument("--frames", type=int, nargs="+", default=[0, 1], help="frames to render (default: 0 1)")
    r.add_argument("-D", dest="define", action="append", metavar="NAME=VALUE", help="scene parameter ($NAME)")
    r.add_argument("--spp", type=int, default=None, help="samples per pixel (camera-tracing integrators)")
    r.add_argument("--seed", type=int, default=0)
    r.set_defaults(func=cmd_render)
    i = sub.add_parser("info", help="print an EXR file's mitpiv metadata")
    i.add_argument("file")
    i.set_defaults(func=cmd_info)
    args = p.parse_args(argv)
    try:
        return args.func(args)
    except MitpivError as e:
        print(f"mitpiv: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
