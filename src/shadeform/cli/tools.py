"""The other commands: synthetic scenes and their evaluation, the registries' listings, the demo
and the browser app."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.markup import escape
from rich.table import Table

from shadeform.cli._shell import (
    app,
    check_suffix,
    format_seconds,
    format_vector,
    print_files,
    print_json,
    progress_bar,
    read_light,
    resolve_light,
    stage,
    stderr_console,
    stdout_console,
    write_rgb_png,
)
from shadeform.cli.options import JsonOption, MaxPixelsOption, SlantOption, TableJsonOption, TiltOption
from shadeform.errors import InputError
from shadeform.integration import available_integrators
from shadeform.io.atomic import OutputSet
from shadeform.solvers import available_solvers

# --- synth -------------------------------------------------------------------------------------


@app.command()
def synth(
    scene: Annotated[
        str, typer.Argument(help="Scene: sphere, ellipsoid, cylinder, vase, bowl, saddle, bumps.")
    ],
    output: Annotated[Path, typer.Option("-o", "--output", help="The image, a .png (written 16-bit).")],
    light: Annotated[
        str | None, typer.Option(metavar="X,Y,Z", help="Direction toward the light; 0,0,1 if not given.")
    ] = None,
    slant: SlantOption = None,
    tilt: TiltOption = None,
    noise: Annotated[float, typer.Option(help="Gaussian noise sigma, as a fraction of the albedo.")] = 0.0,
    size: Annotated[int, typer.Option(help="Image side in pixels.")] = 256,
    seed: Annotated[int, typer.Option(help="Noise seed.")] = 0,
    depth_format: Annotated[str, typer.Option(help="File type of the true depth: npy or tiff.")] = "npy",
    as_json: JsonOption = False,
) -> None:
    """Render a synthetic scene and write its ground truth next to it.

    Writes IMAGE (16-bit grey PNG) and, beside it, STEM_mask.png, STEM_depth.npy (or .tiff) and
    STEM_normals.png (16-bit normal map).
    """
    from shadeform import synth as synth_module
    from shadeform.io.maps import save_depth, save_gray, save_normal_map

    check_suffix(output, (".png",), "the image to")
    if depth_format not in ("npy", "tiff"):
        raise InputError(f"bad --depth-format {depth_format!r}; choose npy or tiff")
    light_vector = resolve_light(light, slant, tilt)
    rendered = synth_module.scene(scene, size=size, light=light_vector, noise=noise, seed=seed)

    stem = output.with_suffix("")
    targets = {
        "image": output,
        "mask": Path(f"{stem}_mask.png"),
        "depth": Path(f"{stem}_depth.{depth_format}"),
        "normals": Path(f"{stem}_normals.png"),
    }
    with OutputSet() as outputs:
        temps = {key: outputs.temp(path) for key, path in targets.items()}
        save_gray(rendered.image, temps["image"], bitdepth=16)
        save_gray(rendered.mask.astype(np.float64), temps["mask"], bitdepth=8)
        save_depth(rendered.depth, temps["depth"])
        save_normal_map(rendered.normals, temps["normals"])
        outputs.commit()

    if as_json:
        print_json(
            {
                "command": "synth",
                "scene": scene,
                "size": size,
                "light": rendered.light,
                "noise": noise,
                "seed": seed,
                "files": targets,
            }
        )
        return
    out = stdout_console()
    out.print(
        f"[bold]rendered[/] {scene} ({size}x{size}, light {format_vector(rendered.light)}, noise {noise:g})"
    )
    print_files(
        out,
        [
            (targets["image"], "image, 16-bit grey"),
            (targets["mask"], "true mask (white = object)"),
            (targets["depth"], "true depth, pixel units, NaN off the object"),
            (targets["normals"], "true normals, 16-bit normal map"),
        ],
    )


# --- evaluate ----------------------------------------------------------------------------------


#: Rows beside a solver's own (label, keyword arguments of reconstruct): the 2002 report's
#: propagation, without the integrability refinement.
_VARIANTS = {"propagation": (("propagation (2002, no refinement)", {"solver": "propagation", "refine": 0}),)}


def _evaluated(selected: list[str] | None) -> list[tuple[str, dict]]:
    """(label, keyword arguments of reconstruct) of every row the table compares: each registered
    solver (or those named, comma-separated or repeated) with its defaults, then its variants."""
    from shadeform.solvers import SOLVERS

    names = [name.strip() for item in selected or () for name in item.split(",") if name.strip()]
    runs = []
    for name in names or SOLVERS.names():
        SOLVERS.get(name)  # an unknown name is refused before any work, listing the registered
        runs += [(name, {"solver": name}), *_VARIANTS.get(name, ())]
    return runs


@app.command()
def evaluate(
    size: Annotated[int, typer.Option(help="Side of the synthetic images in pixels.")] = 256,
    scenes: Annotated[
        list[str] | None,
        typer.Option(
            "--scenes", metavar="NAMES", help="Scenes to run, comma-separated or repeated; all if not given."
        ),
    ] = None,
    solvers: Annotated[
        list[str] | None,
        typer.Option(
            "--solvers",
            "--methods",  # its name before the rename, for one release
            metavar="NAMES",
            help="Solvers to run (`shadeform solvers`), comma-separated or repeated; every registered "
            "one if not given, each with its defaults.",
        ),
    ] = None,
    as_json: TableJsonOption = False,
    fuse: Annotated[
        bool,
        typer.Option(
            "--fuse",
            help="Instead: the closed synthetic objects from 4 turntable views, each solved from its "
            "photo, fused into one model (shadeform.fuse), scored against the true surface.",
        ),
    ] = False,
) -> None:
    """Run the solvers on the synthetic scenes (light +z, no noise) and print their errors."""

    import shadeform
    from shadeform import metrics
    from shadeform import synth as synth_module

    if fuse:
        return _evaluate_fusion(size, as_json)

    names = [name.strip() for item in scenes or () for name in item.split(",") if name.strip()]
    names = names or list(synth_module.SCENES)
    for name in names:
        if name not in synth_module.SCENES:
            raise InputError(f"unknown scene {name!r}; choose from: {', '.join(synth_module.SCENES)}")
    evaluated = _evaluated(solvers)

    runs = []  # (scene name, concave regions given, row label, reconstruct kwargs)
    for name in names:
        marked = bool(synth_module.concave_regions(name, size=size)["regions"])
        for label, kwargs in evaluated:
            runs.append((name, False, label, kwargs))
            if marked:
                runs.append((name, True, label, kwargs))

    rows = []
    with progress_bar(stderr_console()) as progress:
        task = progress.add_task("compiling", total=len(runs))
        # one tiny run first, so the compile/cache-load time is not billed to the first row
        warm = synth_module.scene("sphere", size=16)
        shadeform.reconstruct(warm.image, mask=warm.mask)
        for name, with_region, label, kwargs in runs:
            progress.update(task, description=f"{name}: {label}")
            scene = synth_module.scene(name, size=size)
            concave = synth_module.concave_regions(name, size=size) if with_region else None
            start = time.perf_counter()
            rec = shadeform.reconstruct(
                scene.image, mask=scene.mask, light=scene.light, concave=concave, **kwargs
            )
            seconds = time.perf_counter() - start
            rows.append(
                {
                    "scene": name,
                    "concave_region": with_region,
                    "label": label,
                    **kwargs,
                    "angular_error_deg": metrics.angular_error(rec.normals, scene.normals),
                    "depth_error_pct": metrics.depth_error(rec.depth, scene.depth, fit="offset"),
                    "seconds": seconds,
                    **(
                        {"solver_options": rec.info["solver_options"]} if "solver_options" in rec.info else {}
                    ),
                }
            )
            progress.advance(task)

    if as_json:
        print_json({"command": "evaluate", "size": size, "light": [0, 0, 1], "noise": 0, "rows": rows})
        return
    table = Table(
        title=f"Synthetic scenes, {size}x{size}, light +z, no noise",
        caption="angle: mean angular error of the normals; depth: RMSE as % of the true depth range, "
        "after fitting the free offset",
    )
    table.add_column("scene")
    table.add_column("solver")
    table.add_column("angle (°)", justify="right", no_wrap=True, min_width=9)
    table.add_column("depth (%)", justify="right", no_wrap=True, min_width=9)
    table.add_column("time", justify="right", no_wrap=True, min_width=7)
    for row in rows:
        scene_label = row["scene"]
        if row["concave_region"]:
            scene_label += ", concave regions drawn"
        table.add_row(
            scene_label,
            row["label"],
            f"{row['angular_error_deg']:.2f}",
            f"{row['depth_error_pct']:.2f}",
            format_seconds(row["seconds"]),
        )
    stdout_console().print(table)


def _evaluate_fusion(size: int, as_json: bool) -> None:
    """``evaluate --fuse``: each closed object from 4 turntable views, solved and fused."""
    import shadeform
    from shadeform import metrics, synth

    angles = (0.0, 90.0, 180.0, 270.0)
    rows = []
    with progress_bar(stderr_console()) as progress:
        task = progress.add_task("fusing", total=len(synth.CLOSED_OBJECTS))
        for name in synth.CLOSED_OBJECTS:
            progress.update(task, description=f"{name}: 4 views")
            truth = synth.closed_object(name, size=size)
            views = synth.render_views(name, angles, size=size)
            recs = [shadeform.reconstruct(v.image, mask=v.mask, light=(0, 0, 1)) for v in views]

            def resolve(i, regions, views=views):
                return shadeform.reconstruct(
                    views[i].image, mask=views[i].mask, light=(0, 0, 1), concave=regions
                )

            start = time.perf_counter()
            mesh = shadeform.fuse(list(zip(recs, angles)), resolve=resolve)
            seconds = time.perf_counter() - start
            got = metrics.surface_scores(mesh, truth.surface_points(200_000, seed=1)[0], truth.volume)
            rows.append({"object": name, **got, "seconds": seconds, "triangles": mesh.n_faces})
            progress.advance(task)
    if as_json:
        print_json({"command": "evaluate", "fuse": True, "size": size, "angles": angles, "rows": rows})
        return
    table = Table(
        title=f"Closed objects, 4 turntable views of {size}x{size}, light +z, each view solved alone, "
        "its unsure areas settled by the others' silhouettes, fused",
        caption="Chamfer: % of the diagonal after the free translation; F-score at 1 % of the diagonal; "
        "volume error signed (positive: too large); fuse time includes solving views again to settle them",
    )
    for column in ("object", "Chamfer (%)", "F-score (%)", "volume (%)", "watertight", "fuse time"):
        table.add_column(column, justify="left" if column == "object" else "right")
    for row in rows:
        table.add_row(
            row["object"],
            f"{row['chamfer']:.2f}",
            f"{row['f_score']:.1f}",
            f"{row['volume_error']:+.1f}",
            "yes" if row["watertight"] else "NO",
            format_seconds(row["seconds"]),
        )
    stdout_console().print(table)


# --- formats -----------------------------------------------------------------------------------


@app.command()
def formats(
    as_json: TableJsonOption = False,
) -> None:
    """List the mesh formats `reconstruct -o` can write."""
    from shadeform import available_formats

    registry = available_formats()
    if as_json:
        print_json({"command": "formats", "formats": registry})
        return
    table = Table(title="Mesh formats (picked by the -o suffix)")
    table.add_column("suffix", style="bold")
    table.add_column("format")
    for suffix, description in registry.items():
        table.add_row(suffix, description)
    stdout_console().print(table)


# --- solvers -----------------------------------------------------------------------------------


@app.command()
def solvers(
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object instead of the tables.")
    ] = False,
) -> None:
    """List the solvers `reconstruct --solver` takes (with their own `--option`s) and the
    integrators of `--integrator`."""
    from shadeform.solvers import AUTO, SOLVERS

    rows = [
        {
            "name": AUTO,
            "lights": "any",
            "depth": "the chosen solver's",
            "description": available_solvers()[AUTO],
        }
    ]
    for s in SOLVERS.entries():
        row = {
            "name": s.name,
            "lights": s.lights,
            "depth": s.integrator or s.depth,
            "description": s.description,
        }
        if s.options:  # the built-in solvers have none, and their rows stay as they were
            row["options"] = [option.describe() for option in s.options]
        rows.append(row)
    if as_json:
        print_json({"command": "solvers", "solvers": rows, "integrators": available_integrators()})
        return
    table = Table(title="Solvers (--solver)")
    for column in ("solver", "lights", "depth by", "what it does"):
        table.add_column(column, style="bold" if column == "solver" else None)
    for row in rows:
        options = "".join(
            f"\n--option {o['name']}={o['default']} ({o['type']}): {o['help']}"
            for o in row.get("options", ())
        )
        table.add_row(row["name"], row["lights"], row["depth"], escape(row["description"] + options))
    out = stdout_console()
    out.print(table)
    table = Table(title="Integrators (--integrator)")
    table.add_column("integrator", style="bold")
    table.add_column("what it does")
    for name, text in available_integrators().items():
        table.add_row(name, text)
    out.print(table)


# its name before the rename, for one release
app.command("methods", hidden=True, help="Old name of `shadeform solvers`.")(solvers)


# --- demo --------------------------------------------------------------------------------------


@app.command()
def demo(
    out: Annotated[Path, typer.Option("--out", help="Folder for the results (created if missing).")] = Path(
        "out/demo"
    ),
    example: Annotated[str, typer.Option(help="Example to run: coin, or synth:SCENE.")] = "coin",
    step: Annotated[
        int | None, typer.Option(min=1, help="Mesh step in pixels; the example's own if not given.")
    ] = None,
    size: Annotated[int | None, typer.Option(help="Image side for synth: examples.")] = None,
) -> None:
    """Reconstruct a shipped example photo: writes meshes, the normal map and result.png."""
    import shadeform
    from shadeform.examples import load_example
    from shadeform.io.maps import save_gray, save_normal_map
    from shadeform.render import result_picture

    err = stderr_console()
    timings: dict[str, float] = {}
    total = time.perf_counter()
    image, info = load_example(example, size=size)
    mesh_step = info["step"] if step is None else step
    with stage(
        err,
        f"reconstructing the example '{escape(example)}' (the very first run also compiles the numba kernels: about a minute)",
        timings,
        "reconstruct",
    ):
        rec = shadeform.reconstruct(
            image, light=info["light"], mask=info["mask"], filter=info["filter"], solver=info["solver"]
        )
    with stage(err, "building the mesh", timings, "mesh"):
        mesh = shadeform.to_mesh(rec, step=mesh_step)
    with stage(err, "drawing result.png", timings, "picture"):
        picture = result_picture(image, rec.normals, mesh)

    files = [
        ("input.png", "the input photo (16-bit grey)"),
        ("normals.png", "recovered normal map (16-bit, RGB = (n + 1) / 2)"),
        ("model.wrl", "mesh, VRML 2.0"),
        ("model.iv", "mesh, Open Inventor 2.1"),
        ("model.glb", "mesh, glTF 2.0 binary"),
        ("result.png", "input | normal map | shaded 3D view"),
    ]
    with stage(err, "writing files", timings, "write"), OutputSet() as outputs:
        outputs.make_folder(out)
        temps = {name: outputs.temp(out / name) for name, _ in files}
        save_gray(image, temps["input.png"], bitdepth=16)
        save_normal_map(rec.normals, temps["normals.png"])
        for name in ("model.wrl", "model.iv", "model.glb"):
            shadeform.export(mesh, temps[name])
        write_rgb_png(picture, temps["result.png"])
        outputs.commit()
    timings["total"] = time.perf_counter() - total

    console = stdout_console()
    console.print(f"[bold]demo[/] {escape(info['description'])}")
    console.print(f"  source {escape(info['source'])}")
    console.print(
        f"  {int(rec.mask.sum()):,} object pixels -> {mesh.n_vertices:,} vertices, {mesh.n_faces:,} triangles "
        f"(step {mesh_step}) in {format_seconds(timings['total'])}"
    )
    if "light_estimate" in rec.info:
        console.print(f"  light{read_light(rec.info)}")
    console.print(f"[bold]wrote[/] to {escape(str(out))}/")
    print_files(console, [(out / name, what) for name, what in files])
    console.print(
        "  open result.png to see it; view the .glb in any glTF viewer (e.g. Blender) or the .wrl in a "
        "VRML viewer; try your own photo with: shadeform reconstruct PHOTO -o model.glb"
    )


# --- app ---------------------------------------------------------------------------------------


@app.command("app")
def app_command(
    image: Annotated[
        str | None,
        typer.Argument(
            help="Photo to open at start, or a shipped example (coin, synth:bowl, ...).", show_default=False
        ),
    ] = None,
    port: Annotated[int, typer.Option(min=0, max=65535, help="Port to serve on (0: any free port).")] = 8000,
    host: Annotated[str, typer.Option(help="Address to bind; loopback unless --allow-remote.")] = "127.0.0.1",
    allow_remote: Annotated[
        bool,
        typer.Option(
            "--allow-remote",
            help="Allow binding a non-loopback address: anyone who can reach it can use the app.",
        ),
    ] = False,
    no_browser: Annotated[bool, typer.Option("--no-browser", help="Do not open a web browser.")] = False,
    sessions: Annotated[
        Path | None,
        typer.Option(
            help="SQLite file that keeps the photos opened, so that sessions outlive a restart "
            "(default: app.sqlite3 in the user's data folder).",
            show_default=False,
        ),
    ] = None,
    no_sessions: Annotated[
        bool, typer.Option("--no-sessions", help="Keep nothing on disk: a restart forgets the photos opened.")
    ] = False,
    max_pixels: MaxPixelsOption = None,
) -> None:
    """Start the browser app: open a photo, draw concave regions, see and export the 3D model."""
    import ipaddress
    import socket
    import sqlite3
    import threading
    import webbrowser

    try:
        import uvicorn

        from shadeform.app.guard import AppLimits
        from shadeform.app.server import LOOPBACK_HOSTS, create_app
        from shadeform.app.sessions import data_folder
    except ImportError as missing:
        raise InputError(
            f"the app needs {missing.name or 'its web server'}, which is not installed; "
            "install shadeform with its app extra: pip install 'shadeform[app]'"
        ) from None
    from shadeform.examples import EXAMPLES

    try:
        loopback = host == "localhost" or ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        loopback = False
    if not loopback and not allow_remote:
        raise InputError(
            f"--host {host} is not a loopback address; other machines could use the app. "
            "Add --allow-remote if that is what you want"
        )
    initial = None
    if image is not None:
        # the user's own argument: a file, else an example name
        if Path(image).exists() or image not in EXAMPLES:
            initial = Path(image)
            if not initial.is_file():
                raise InputError(
                    f"no such image file or example: '{image}'; give a photo's path or one "
                    f"of: {', '.join(EXAMPLES)}"
                )
        else:
            initial = image
    err = stderr_console()
    with err.status("opening the image", spinner="dots"):
        # warm: the numba kernels compile (or load) in the background, so the first click does not wait
        # the server's own pixel limit (it keeps several photos in memory) unless raised
        limits = AppLimits() if max_pixels is None else AppLimits(max_pixels=max_pixels)
        if no_sessions and sessions is not None:
            raise InputError("give --sessions FILE or --no-sessions, not both")
        store = None if no_sessions else sessions or data_folder() / "app.sqlite3"
        try:
            application = create_app(
                initial_image=initial,
                allowed_hosts=None if allow_remote else LOOPBACK_HOSTS,
                warm=True,
                limits=limits,
                sessions=store,
            )
        except sqlite3.Error as err:
            raise InputError(
                f"cannot use the session file '{store}' ({err}); give another with --sessions FILE, or --no-sessions"
            ) from None
    # bind first, so that the printed address (and port 0's pick) is the one that answers
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host.strip("[]"), port))
    except OSError as error:
        sock.close()
        raise InputError(
            f"cannot listen on {host}:{port} ({error.strerror}); choose another --port"
        ) from None
    bound_port = sock.getsockname()[1]
    shown_host = f"[{host.strip('[]')}]" if ":" in host else host
    url = f"http://{shown_host}:{bound_port}/"
    if not loopback:
        err.print(
            f"[bold yellow]warning:[/] serving on {escape(host)}, not loopback: anyone who can reach "
            "this address can use the app and read the images opened in it"
        )
    stdout_console().print(f"[bold]shadeform app[/] at {escape(url)}  (Ctrl+C stops it)")
    if not no_browser and _has_display():
        threading.Timer(0.5, webbrowser.open, args=(url,)).start()
    config = uvicorn.Config(application, log_level="warning")
    uvicorn.Server(config).run(sockets=[sock])


def _has_display() -> bool:
    """Whether a browser could show a window here (a desktop session, or macOS/Windows)."""
    import sys

    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))
