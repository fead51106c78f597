"""``shtools spheres tree`` and ``shtools spheres bind``: sphere hierarchies and skin binding.

The ``spheres`` click group (``shtools/cli/spheres.py``) registers the two
commands defined here.  Both are thin: read the sphere set, call
:func:`shtools.geometry.sphere_tree.build_tree` or
:func:`shtools.geometry.binding.bind_spheres`, write one asset, report.
"""

from __future__ import annotations

import click

from shtools.cli._common import (
    InputPath,
    errors_name,
    json_option,
    option_type,
    output_option,
    progress,
    report,
)
from shtools.cli._outputs import guard_outputs
from shtools.geometry.fit_methods import SPHERE_SPACES


@click.command("tree")
@click.argument("spheres_path", metavar="SPHERES", type=InputPath())
@output_option
@click.option("--branching", default=4, show_default=True, type=option_type("branching"),
              help="Target average number of children per inner node.")
@click.option("--seed", default=0, show_default=True, type=option_type("seed"),
              help="Seed of the Lloyd clustering (same seed -> identical tree).")
@json_option
@errors_name("spheres_path")
def tree(spheres_path, output, branching, seed, as_json):
    """Build a bounding-sphere hierarchy over the spheres of SPHERES (bottom-up Lloyd).

    Every parent is the minimal sphere bounding its children's spheres.
    """
    from shtools.geometry.assets import tree_to_file
    from shtools.geometry.sphere_tree import tree_statistics

    guard_outputs({"-o": output}, [spheres_path])
    result = tree_to_file(spheres_path, output, branching=branching, seed=seed,
                          progress=progress)
    stats = tree_statistics(result)
    summary = {"output": output, **stats}
    report(
        summary,
        as_json,
        f"wrote {output}: {stats['nodes']} nodes over {stats['leaves']} leaves, "
        f"{stats['levels']} levels, average branching {stats['average_branching']:.2f}",
    )


@click.command("bind")
@click.argument("spheres_path", metavar="SPHERES", type=InputPath())
@click.argument("rig_path", metavar="RIGGED", type=InputPath())
@output_option
@click.option("--bones-per-sphere", default=4, show_default=True,
              type=option_type("bones_per_sphere"),
              help="Bones kept per sphere centre (the rest is folded into the kept ones).")
@click.option("--check-frames", default=16, show_default=True,
              type=option_type("check_frames"),
              help="Frames per animation at which the posed spheres' coverage of the "
                   "skinned vertices is measured for the summary (0: skip).")
@click.option("--cover-animations", is_flag=True,
              help="Grow each radius so the sphere keeps covering its rest vertices at "
                   "every checked frame of every animation in RIGGED (the paper keeps the "
                   "rest radii); the fitted radii are kept as 'fit_radii'.")
@click.option("--space", type=click.Choice(SPHERE_SPACES), default="auto",
              show_default=True,
              help="Space of the sphere set: 'bind' (the rig's POSITION data), 'scene' (the "
                   "glTF as placed in its scene, what 'shtools spheres fit RIG.glb' sees), "
                   "or 'auto' (whichever the spheres cover).  Output is in bind space.")
@json_option
def bind(spheres_path, rig_path, output, bones_per_sphere, check_frames, cover_animations,
         space, as_json):
    """Bind the spheres of SPHERES to the skin of the glTF rig RIGGED (.glb/.gltf).

    Mean value coordinates of each centre on the rest (bind-space) mesh,
    premultiplied by the vertex bone weights, keep a few bones per sphere; radii
    are kept unless --cover-animations.  The spheres must be in the rig's bind
    space (fit them to the rig's rest mesh).
    """
    from shtools.data_formats.bound import write_bound
    from shtools.geometry.assets import read_sphere_set
    from shtools.geometry.binding import bind_sphere_set
    from shtools.geometry.skin import load_skinned_gltf

    guard_outputs({"-o": output}, [spheres_path, rig_path])
    centers, radii = read_sphere_set(spheres_path)
    model = load_skinned_gltf(rig_path)
    bound = bind_sphere_set(centers, radii, model, bones_per_sphere=bones_per_sphere,
                            space=space, cover_animations=cover_animations,
                            check_frames=check_frames, spheres_path=spheres_path,
                            rig_path=rig_path)
    write_bound(
        output,
        bound.centers,
        bound.radii,
        bound.binding,
        fit_radii=bound.fit_radii if cover_animations else None,
        inputs={"spheres": spheres_path, "rig": rig_path},
        parameters={"bones_per_sphere": bound.bones_per_sphere, "sphere_space": bound.space,
                    "cover_animations": bool(cover_animations),
                    "check_frames": check_frames},
    )
    summary = {"output": output, **bound.summary(model)}
    coverage, binding = bound.coverage, bound.binding
    bones_per_sphere = bound.bones_per_sphere
    cov = coverage.get("posed_vertex_coverage")
    human = (
        f"wrote {output}: {summary['spheres']} spheres bound to {summary['joints']} joints "
        f"({bones_per_sphere} per sphere)"
        + (f", posed vertex coverage {cov:.3f}" if cov is not None else "")
        + ("" if binding.mesh_closed else "; rest mesh is not closed (see --json)")
    )
    report(summary, as_json, human)
