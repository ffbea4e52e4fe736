"""Movable objects out of the static map (the ``lift_movables`` step's algorithm): find the scanned vehicles, riders and pedestrians in the
labelled textured mesh, cut them out, close the ground beneath them, and describe each as an actor.

Why: a parked car in the static map is collidable geometry nobody can move; a car parked on a
driving lane puts a solid block over lane waypoints. Simulators want such objects as actors
(CARLA: a ``vehicle.*`` / ``walker.*`` blueprint; Isaac: a separate prim without a static
collider).

The labels are noisy (on the demo the predicted "car" covers the ground around the cars too), so
the class alone does not make an object; 3D cues decide (all in the site frame, metres, z up):

1. **Ground height** on a grid (``cell_m``): the up-facing vertices (normal z >= ``up_normal_z``)
   no higher than ``ground_tol_m`` above the lowest up-facing vertex within ``ground_window_m``
   are ground; a cell's ground height is their mean; cells without ground (under a car's roof)
   take the nearest ground cell's height. The window is wider than any vehicle is wide, so a roof
   never counts as ground. Every vertex gets ``h`` = height above that ground.
2. **Candidates**: vertices with a movable label (person 11, rider 12, car 13, truck 14, bus 15,
   train 16, motorcycle 17, bicycle 18) and ``h > min_height_m``; movable-labelled vertices below
   that are ground, whatever the label says.
3. **Instances**: candidates clustered in 3D (``cluster_gap_m``); a cluster is an object when it
   stands up (its top at least the class's minimum height, at most its maximum), has a footprint
   no longer than the class allows, and has walls (at least ``min_vertical_share`` of its
   vertices with a near-horizontal normal). Flat patches (a painted bay, a ramp labelled car) fail
   the first or the last test; a building wall labelled car fails the size test. The class is the
   votes' first that the shape fits; a cluster with a vehicle's width and walls that fits no voted
   class is a car or truck by size (``choose_class``), and one longer than a car is first cut where its
   height dips (cars parked bumper to bumper, ``split_along``). Labels and shape are not enough: the object
   must also have a body (its class's minimum width), stand on the ground and, where the recipe has the 3D
   classifier, be movable to its votes (:mod:`.cues`); else it stays static.
4. **Faces of an instance**: grown over the mesh from the cluster's faces through faces whose
   corners all lie above ``cut_height_m``, inside the cluster's oriented footprint widened by
   ``margin_m`` and below its top + ``margin_m``, whatever their label (wheels and windows are
   often labelled something else). Bits of surface left inside the footprint with no connection
   to the ground outside it (the reconstructed underside) go with the object.
5. **Fill**: every boundary loop the cut opened is closed with a patch at the ring's height (the
   local ground): a constrained Delaunay triangulation of the loop seen from above with grid points
   inside at the ground's height (``twinkit.street.holes.close_hole``); where the outline is no
   simple polygon seen from above, at the ring's heights (``span``: a fan round the centroid where the
   loop is star-shaped, else ear clipping of its outline). Each patch face copies the texture coordinates of the
   nearest ground face of the ring (a plausible piece of the surrounding ground), and its vertices
   take the ring's majority ground class (road, sidewalk, terrain). No open border is left unless
   a loop cannot be closed safely (it runs off the footprint: the object stood at the scan's edge;
   reported).
6. **Labels left**: movable labels that stay in the static mesh (flat ground voted car, rejected
   clusters) take the label of the nearest non-movable vertex (a ground class when the vertex is
   at ground height), so the static map carries no movable class.

Where each stage lives: :func:`.lift.ground_under` (1, the street library's ``LocalGround``), :mod:`.kinds`, :mod:`.detect` and :mod:`.cues` (2-4), :mod:`.fill` (5),
:func:`.lift.relabel_left` (6), :mod:`.lift` (the order of the stages), :mod:`.actors` (the CARLA
blueprint, ``actors.json`` and one PLY per object), :mod:`.options` (every threshold).
"""
from .actors import ACTORS, load_actors, suggest_blueprint
from .detect import Instance, oriented_box, split_along
from .fill import border_edges, open_border_near
from .kinds import MOVABLE, NAMES, refine_class
from .lift import LiftResult, lift_movables
from .options import LiftOptions

__all__ = ["ACTORS", "Instance", "LiftOptions", "LiftResult", "MOVABLE", "NAMES", "border_edges", "lift_movables",
           "load_actors", "oriented_box", "open_border_near", "refine_class", "split_along", "suggest_blueprint"]
