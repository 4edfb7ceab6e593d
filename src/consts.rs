// Constants shared by Rust and GLSL. build.rs passes `SHADER_DEFINES` to every
// kernel as `#define NAME value`, so each value is written once, here.

/// Invocations per workgroup of the trace kernel (one ray per invocation).
pub const TRACE_WORKGROUP_SIZE: u32 = 64;
/// Deepest leaf the builder may create; also bounds the full traversal stack.
pub const MAX_TREE_DEPTH: u32 = 48;
/// Entries of the full per-ray stack (`stack` variant): one push per level at most.
pub const MAX_STACK: u32 = MAX_TREE_DEPTH + 1;
/// Traversal steps after which a ray gives up and is reported as capped.
pub const MAX_TRAVERSAL_STEPS: u32 = 16384;
/// The watertight test bounds each sheared vertex coordinate's error by
/// `2^-EDGE_GAMMA_LOG2` times its magnitude before the shear cancelled (32
/// roundings of 2^-24, about 6 times the worst case of 5) and carries that
/// through the edge functions' products (`edge_error` in triangle.glsl); an edge
/// function within its bound is redone exactly (float-float).
pub const EDGE_GAMMA_LOG2: u32 = 19;
/// The exact orientations (edge signs, plane sides; `orient_sign` in src/ff.rs)
/// take vectors scaled to about 1 and count a determinant within
/// `2^-ORIENT_ZERO_LOG2` of 0 as 0: far below every rounding the kernels make,
/// above the error of terms a GPU without denormals flushes to 0. An edge
/// function whose sign they correct takes that magnitude.
pub const ORIENT_ZERO_LOG2: u32 = 100;
/// `2^-ORIENT_ZERO_LOG2` (`ORIENT_ZERO` in ff.glsl).
pub const ORIENT_ZERO: f32 = 1.0 / (1u128 << ORIENT_ZERO_LOG2) as f32;
/// The traversals' split decisions and early exits are widened by
/// `2^-TRAVERSAL_EPS_LOG2` relative (about 8 f32 ulps, more than the rounding of
/// two ray/plane distances), so that rounding never skips a cell the ray enters
/// (conservative traversal in the spirit of Ize 2013).
pub const TRAVERSAL_EPS_LOG2: u32 = 20;
/// Robust rays whose origin lies more than this many scene diagonals before
/// their entry into the scene box are traversed from that entry (the segment
/// frame of `glsl/traverse/segment.glsl`), so that the widening above stays a
/// fraction of the scene, not of a huge `t`. Nearer rays are traversed from their own origin.
pub const SHIFT_DIAGONALS: u32 = 16;
/// Largest short stack (`short-stack` variants); the paper used 3.
pub const MAX_SHORT_STACK: u32 = 8;
/// The 8-byte kd-tree node (`KdNode`, `glsl/shared/kdnode.glsl`): bits of its
/// second word that hold the split axis (0..=2) or `NODE_LEAF`; in a leaf, the
/// bits above hold the primitive count.
pub const NODE_TAG_BITS: u32 = 2;
/// The tag (low `NODE_TAG_BITS` of the second word) of a leaf.
pub const NODE_LEAF: u32 = 3;
/// Interior node, second word: set when the below child is an empty leaf.
pub const NODE_BELOW_EMPTY: u32 = 1 << 2;
/// Interior node, second word: set when the above child is an empty leaf.
pub const NODE_ABOVE_EMPTY: u32 = 1 << 3;
/// Interior node, second word: the above child's index starts at this bit
/// (below it: the axis and the two empty-child flags).
pub const NODE_CHILD_SHIFT: u32 = 4;
/// `ropes` entry of a face on the scene boundary.
pub const NO_ROPE: u32 = 0xFFFF_FFFF;

/// `Hit::prim_id` of a ray that hit nothing.
pub const PRIM_MISS: u32 = 0xFFFF_FFFF;
/// `Hit::prim_id` of an invalid ray (NaN or infinite origin, NaN or zero direction).
pub const PRIM_INVALID: u32 = 0xFFFF_FFFE;
/// `Hit::prim_id` of a ray whose traversal did not finish (step cap or driver loop cut-off).
pub const PRIM_INCOMPLETE: u32 = 0xFFFF_FFFD;

// Specialization constant ids of the trace kernel (32-bit each; bools as 0/1).
// The variant is not one of them: build.rs compiles one module per variant.
/// Write per-ray counters (`bool`).
pub const TRACE_SPEC_COUNTERS: u32 = 0;
/// Short-stack entries, 1..=`MAX_SHORT_STACK`.
pub const TRACE_SPEC_STACK_SIZE: u32 = 1;
/// Stop at the first hit (shadow rays; `bool`).
pub const TRACE_SPEC_ANY_HIT: u32 = 2;
/// Lanes per packet; 1 = single rays.
pub const TRACE_SPEC_PACKET_WIDTH: u32 = 3;
/// Conservative decisions and the exact fallback near edges (`bool`).
pub const TRACE_SPEC_ROBUST: u32 = 4;
/// The pass (`PASS_*`).
pub const TRACE_SPEC_PASS: u32 = 5;
/// Number of specialization constants of the trace kernel.
pub const TRACE_SPECS: u32 = 6;
/// The ray-query kernel's only specialization constant: stop at the first hit (`bool`).
pub const RQ_SPEC_ANY_HIT: u32 = 0;
/// Number of specialization constants of the ray-query kernel.
pub const RQ_SPECS: u32 = 1;

// Traversal variant ids: the index of a trace kernel's module (`shaders::TRACE`, define `TRACE_MODULE_VARIANT`).
/// Variant id of `stack`: full per-ray stack (pbrt-v3), the baseline.
pub const VARIANT_STACK: u32 = 0;
/// Variant id of `restart`: kd-restart from the root (Foley & Sugerman 2005).
pub const VARIANT_RESTART: u32 = 1;
/// Variant id of `push-down`: kd-restart from the push-down node (Horn et al. 2007).
pub const VARIANT_PUSH_DOWN: u32 = 2;
/// Variant id of `short-stack`: ring-buffer short stack with restart (Horn et al. 2007).
pub const VARIANT_SHORT_STACK: u32 = 3;
/// Variant id of `push-down-short-stack`: short stack plus push-down (Horn et al. 2007).
pub const VARIANT_PUSH_DOWN_SHORT_STACK: u32 = 4;
/// Variant id of `backtrack`: kd-backtrack over parent links (Foley & Sugerman 2005).
pub const VARIANT_BACKTRACK: u32 = 5;
/// Variant id of `ropes`: leaf-to-leaf rope walk (Popov et al. 2007).
pub const VARIANT_ROPES: u32 = 6;

// Descriptor bindings of the trace kernel (set 0).
/// Binding of the kd-tree nodes (8-byte `KdNode`s, read-only).
pub const BINDING_NODES: u32 = 0;
/// Binding of the leaves' triangle index lists (`u32` each, read-only).
pub const BINDING_PRIM_INDICES: u32 = 1;
/// Binding of the triangle vertices (9 `f32` per triangle, read-only).
pub const BINDING_TRIANGLES: u32 = 2;
/// Binding of the input rays (32-byte std430 `Ray`s, read-only).
pub const BINDING_RAYS: u32 = 3;
/// Binding of the output hits (16-byte std430 `Hit`s, write-only).
pub const BINDING_HITS: u32 = 4;
/// Binding of the per-ray counters (`COUNTERS_PER_RAY` `u32` per ray, write-only).
pub const BINDING_COUNTERS: u32 = 5;
// Side buffers, bound only by the variants that need them (a dummy otherwise).
/// Binding of the parent links (`u32` per node; `backtrack` only).
pub const BINDING_PARENTS: u32 = 6;
/// Binding of the node boxes (6 `f32` per node: min xyz, max xyz; `backtrack` and `ropes`).
pub const BINDING_NODE_BOXES: u32 = 7;
/// Binding of the leaf ropes (6 `u32` per node, `NO_ROPE` on the boundary; `ropes` only).
pub const BINDING_ROPES: u32 = 8;
/// Binding of the careful-pass list of robust single-ray traces (a dummy otherwise):
/// `u32` words, `CAREFUL_HEADER_WORDS` of header (`vkCmdDispatchIndirect` arguments
/// x, y, z, then the count), then the indices of the rays the fast pass left.
pub const BINDING_CAREFUL: u32 = 9;
/// Binding of the coherent order of the rays (`u32` ray indices, read-only; a
/// dummy unless `TraceParams::ordered`): the trace kernel's invocation `i` traces
/// ray `order[i]`.
pub const BINDING_ORDER: u32 = 10;
/// Binding of a device-counted trace's arguments (`INDIRECT_WORDS` `u32`, read-only;
/// a dummy unless `TraceParams::indirect`): the count at `INDIRECT_COUNT`.
pub const BINDING_INDIRECT: u32 = 11;
/// Number of bindings of the trace kernel.
pub const TRACE_BINDINGS: u32 = 12;

// Descriptor bindings of the two-level kernel (glsl/trace_twolevel.comp, set 0).
/// Binding of every geometry's kd-tree nodes, one after another (texels as `BINDING_NODES`).
pub const TL_BINDING_NODES: u32 = 0;
/// Binding of every geometry's triangle references (texels as `BINDING_TRIANGLES`).
pub const TL_BINDING_TRIANGLES: u32 = 1;
/// Binding of the input rays (32-byte `Ray`s, world space).
pub const TL_BINDING_RAYS: u32 = 2;
/// Binding of the output hits (32-byte `GpuInstanceHit`s).
pub const TL_BINDING_HITS: u32 = 3;
/// Binding of the geometries (`GpuGeometry`).
pub const TL_BINDING_GEOMETRIES: u32 = 4;
/// Binding of the instances (`GpuInstance`).
pub const TL_BINDING_INSTANCES: u32 = 5;
/// Binding of the top-level BVH (`TopNode`, the root first).
pub const TL_BINDING_TOP: u32 = 6;
/// Binding of the instance order of the top-level leaves (`u32`).
pub const TL_BINDING_ORDER: u32 = 7;
/// Binding of the careful pass's list (as `BINDING_CAREFUL`; one-instance robust traces).
pub const TL_BINDING_CAREFUL: u32 = 8;
/// Binding of a device-counted trace's arguments (as `BINDING_INDIRECT`; a
/// dummy unless `TwoLevelParams::indirect`).
pub const TL_BINDING_INDIRECT: u32 = 9;
/// Number of bindings of the two-level kernel.
pub const TL_BINDINGS: u32 = 10;
/// Specialization constant id of the two-level kernel's one-instance mode (after the trace kernel's).
pub const TL_SPEC_ONE_INSTANCE: u32 = TRACE_SPECS;
/// Entries of the two-level kernel's top-level stack: the BVH's depth must stay below it.
pub const MAX_TOP_STACK: u32 = 64;

// The coherent order of a batch (`glsl/order_rays.comp`, `RayOrder::Coherent`).
/// Bits per axis of the origin's cell in the scene box (a Morton code of 3 × this).
pub const ORDER_CELL_BITS: u32 = 4;
/// Workgroup size of the ordering kernel (its scan step runs one workgroup).
pub const ORDER_WORKGROUP_SIZE: u32 = 256;
/// Buckets of the counting sort: 8 octants × the cells, then one more run of
/// `ORDER_WORKGROUP_SIZE` whose last bucket holds the invalid rays.
pub const ORDER_BUCKETS: u32 = (8 << (3 * ORDER_CELL_BITS)) + ORDER_WORKGROUP_SIZE;
/// Specialization constant id of the ordering kernel's step.
pub const ORDER_SPEC_STEP: u32 = 0;
/// Step: count the rays of each bucket.
pub const ORDER_STEP_COUNT: u32 = 0;
/// Step: the buckets' start offsets (one workgroup).
pub const ORDER_STEP_SCAN: u32 = 1;
/// Step: each ray's place in the order.
pub const ORDER_STEP_SCATTER: u32 = 2;
/// Binding of the ordering kernel's rays (as the trace kernel's).
pub const ORDER_BINDING_RAYS: u32 = 0;
/// Binding of its bucket counts and offsets (`ORDER_BUCKETS` `u32`).
pub const ORDER_BINDING_BUCKETS: u32 = 1;
/// Binding of the order it writes (`u32` per ray).
pub const ORDER_BINDING_LIST: u32 = 2;
/// Binding of a device-counted trace's arguments (as `BINDING_INDIRECT`).
pub const ORDER_BINDING_INDIRECT: u32 = 3;
/// Number of bindings of the ordering kernel.
pub const ORDER_BINDINGS: u32 = 4;
// Descriptor bindings of the ray-query kernel (`glsl/trace_ray_query.comp`, set 0).
/// Binding of the driver's top-level acceleration structure over the scene.
pub const RQ_BINDING_SCENE: u32 = 0;
/// Binding of the scene's triangle index of each triangle in the driver's order (`u32` each).
pub const RQ_BINDING_PRIM_IDS: u32 = 1;
/// Binding of the input rays (32-byte std430 `Ray`s, read-only).
pub const RQ_BINDING_RAYS: u32 = 2;
/// Binding of the output hits (16-byte std430 `Hit`s, write-only).
pub const RQ_BINDING_HITS: u32 = 3;
/// Binding of a device-counted trace's arguments (as `BINDING_INDIRECT`).
pub const RQ_BINDING_INDIRECT: u32 = 4;
/// Number of bindings of the ray-query kernel.
pub const RQ_BINDINGS: u32 = 5;

// Device-counted traces (`Tracer::record_binding_indirect`, glsl/indirect_args.comp):
// a one-invocation kernel turns the caller's count into a binding's arguments.
/// `u32` words of a binding's arguments: the trace kernel's dispatch (x, y, z),
/// the count, the ordering kernel's dispatch (x, y, z), padding.
pub const INDIRECT_WORDS: u32 = 8;
/// Word of the count (at most the binding's capacity) in a binding's arguments.
pub const INDIRECT_COUNT: u32 = 3;
/// Word of the ordering kernel's dispatch arguments in a binding's arguments.
pub const INDIRECT_ORDER_ARGS: u32 = 4;
/// Binding of the arguments kernel's source: the caller's counts (`u32`, read-only).
pub const ARGS_BINDING_SOURCE: u32 = 0;
/// Binding of the arguments kernel's output: the binding's arguments.
pub const ARGS_BINDING_ARGS: u32 = 1;
/// Number of bindings of the arguments kernel.
pub const ARGS_BINDINGS: u32 = 2;
/// Words before the ray indices in the careful-pass list.
pub const CAREFUL_HEADER_WORDS: u32 = 4;
/// The word of the careful-pass list's header that counts the listed rays
/// (after the indirect dispatch's x, y, z).
pub const CAREFUL_COUNT: u32 = 3;
/// Workgroups per row (x) of the careful pass's indirect dispatch: Vulkan's
/// guaranteed minimum of `maxComputeWorkGroupCount`; more listed rays take more rows (y).
pub const CAREFUL_MAX_GROUPS: u32 = 65535;

// The interface of the raster pipeline (`glsl/raster_visibility.vert`, `.frag`).
/// Vertex buffer binding of the scene's vertices (3 per triangle, `vec3` each).
pub const RASTER_VERTEX_BINDING: u32 = 0;
/// Vertex attribute location of the position.
pub const RASTER_LOCATION_POSITION: u32 = 0;
/// Location of the triangle number passed from the vertex to the fragment stage.
pub const RASTER_LOCATION_PRIM: u32 = 0;
/// Location of the fragment output: the visibility buffer, color attachment 0.
pub const RASTER_LOCATION_VISIBILITY: u32 = 0;

// Descriptor bindings of the layout probe (`glsl/layout_probe.comp`, tests only).
/// Element 1 of a `Ray` buffer.
pub const PROBE_BINDING_RAYS: u32 = 0;
/// Element 1 of a `Hit` buffer.
pub const PROBE_BINDING_HITS: u32 = 1;
/// Elements 1 and 2 of a kd-tree node buffer (an interior node and a leaf).
pub const PROBE_BINDING_NODES: u32 = 2;
/// Element 1 of a `RasterView` buffer.
pub const PROBE_BINDING_RASTER_VIEWS: u32 = 3;
/// The words written back.
pub const PROBE_BINDING_WORDS: u32 = 4;
/// Number of bindings of the layout probe.
pub const PROBE_BINDINGS: u32 = 5;

// The passes of the trace kernel (specialization constant `TRACE_SPEC_PASS`).
/// One pass: packets, the plain kernels, and variants traced carefully at once.
pub const PASS_ONE: u32 = 0;
/// Robust single rays, first pass: trace fast; list the rays that need the careful pass.
pub const PASS_FAST: u32 = 1;
/// Robust single rays, second pass (dispatched indirectly): trace the listed rays carefully.
pub const PASS_CAREFUL: u32 = 2;

// Per-ray counters written when counters are on (u32 each), indices within a ray's record.
/// Counter index of node fetches (interior and leaf, backtrack climbs included).
pub const COUNTER_NODES: u32 = 0;
/// Counter index of leaves visited.
pub const COUNTER_LEAVES: u32 = 1;
/// Counter index of ray/triangle tests.
pub const COUNTER_TRIANGLES: u32 = 2;
/// Counter index of restarts (kd-restart, push-down, empty short stack), backtracks or rope hops.
pub const COUNTER_RESTARTS: u32 = 3;
/// Counter index of traversal loop iterations.
pub const COUNTER_STEPS: u32 = 4;
/// Counter index of short-stack entries dropped because the stack was full.
pub const COUNTER_DROPS: u32 = 5;
/// `u32` slots per ray in the counter buffer (6 used, padded to 8).
pub const COUNTERS_PER_RAY: u32 = 8;

/// Every constant above, as `#define`s for the shaders.
pub const SHADER_DEFINES: &[(&str, u32)] = &[
    ("TRACE_WORKGROUP_SIZE", TRACE_WORKGROUP_SIZE),
    ("MAX_TREE_DEPTH", MAX_TREE_DEPTH),
    ("MAX_STACK", MAX_STACK),
    ("MAX_TRAVERSAL_STEPS", MAX_TRAVERSAL_STEPS),
    ("MAX_SHORT_STACK", MAX_SHORT_STACK),
    ("EDGE_GAMMA_LOG2", EDGE_GAMMA_LOG2),
    ("ORIENT_ZERO_LOG2", ORIENT_ZERO_LOG2),
    ("TRAVERSAL_EPS_LOG2", TRAVERSAL_EPS_LOG2),
    ("SHIFT_DIAGONALS", SHIFT_DIAGONALS),
    ("NODE_TAG_BITS", NODE_TAG_BITS),
    ("NODE_LEAF", NODE_LEAF),
    ("NODE_BELOW_EMPTY", NODE_BELOW_EMPTY),
    ("NODE_ABOVE_EMPTY", NODE_ABOVE_EMPTY),
    ("NODE_CHILD_SHIFT", NODE_CHILD_SHIFT),
    ("NO_ROPE", NO_ROPE),
    ("PRIM_MISS", PRIM_MISS),
    ("PRIM_INVALID", PRIM_INVALID),
    ("PRIM_INCOMPLETE", PRIM_INCOMPLETE),
    ("TRACE_SPEC_COUNTERS", TRACE_SPEC_COUNTERS),
    ("TRACE_SPEC_STACK_SIZE", TRACE_SPEC_STACK_SIZE),
    ("TRACE_SPEC_ANY_HIT", TRACE_SPEC_ANY_HIT),
    ("TRACE_SPEC_PACKET_WIDTH", TRACE_SPEC_PACKET_WIDTH),
    ("TRACE_SPEC_ROBUST", TRACE_SPEC_ROBUST),
    ("TRACE_SPEC_PASS", TRACE_SPEC_PASS),
    ("RQ_SPEC_ANY_HIT", RQ_SPEC_ANY_HIT),
    ("VARIANT_STACK", VARIANT_STACK),
    ("VARIANT_RESTART", VARIANT_RESTART),
    ("VARIANT_PUSH_DOWN", VARIANT_PUSH_DOWN),
    ("VARIANT_SHORT_STACK", VARIANT_SHORT_STACK),
    ("VARIANT_PUSH_DOWN_SHORT_STACK", VARIANT_PUSH_DOWN_SHORT_STACK),
    ("VARIANT_BACKTRACK", VARIANT_BACKTRACK),
    ("VARIANT_ROPES", VARIANT_ROPES),
    ("BINDING_NODES", BINDING_NODES),
    ("BINDING_PRIM_INDICES", BINDING_PRIM_INDICES),
    ("BINDING_TRIANGLES", BINDING_TRIANGLES),
    ("BINDING_RAYS", BINDING_RAYS),
    ("BINDING_HITS", BINDING_HITS),
    ("BINDING_COUNTERS", BINDING_COUNTERS),
    ("BINDING_PARENTS", BINDING_PARENTS),
    ("BINDING_NODE_BOXES", BINDING_NODE_BOXES),
    ("BINDING_ROPES", BINDING_ROPES),
    ("BINDING_ORDER", BINDING_ORDER),
    ("BINDING_INDIRECT", BINDING_INDIRECT),
    ("ORDER_BINDING_INDIRECT", ORDER_BINDING_INDIRECT),
    ("RQ_BINDING_INDIRECT", RQ_BINDING_INDIRECT),
    ("INDIRECT_WORDS", INDIRECT_WORDS),
    ("INDIRECT_COUNT", INDIRECT_COUNT),
    ("INDIRECT_ORDER_ARGS", INDIRECT_ORDER_ARGS),
    ("ARGS_BINDING_SOURCE", ARGS_BINDING_SOURCE),
    ("ARGS_BINDING_ARGS", ARGS_BINDING_ARGS),
    ("TL_BINDING_NODES", TL_BINDING_NODES),
    ("TL_BINDING_TRIANGLES", TL_BINDING_TRIANGLES),
    ("TL_BINDING_RAYS", TL_BINDING_RAYS),
    ("TL_BINDING_HITS", TL_BINDING_HITS),
    ("TL_BINDING_GEOMETRIES", TL_BINDING_GEOMETRIES),
    ("TL_BINDING_INSTANCES", TL_BINDING_INSTANCES),
    ("TL_BINDING_TOP", TL_BINDING_TOP),
    ("TL_BINDING_ORDER", TL_BINDING_ORDER),
    ("TL_BINDING_CAREFUL", TL_BINDING_CAREFUL),
    ("TL_BINDING_INDIRECT", TL_BINDING_INDIRECT),
    ("MAX_TOP_STACK", MAX_TOP_STACK),
    ("TL_SPEC_ONE_INSTANCE", TL_SPEC_ONE_INSTANCE),
    ("ORDER_CELL_BITS", ORDER_CELL_BITS),
    ("ORDER_WORKGROUP_SIZE", ORDER_WORKGROUP_SIZE),
    ("ORDER_BUCKETS", ORDER_BUCKETS),
    ("ORDER_SPEC_STEP", ORDER_SPEC_STEP),
    ("ORDER_STEP_COUNT", ORDER_STEP_COUNT),
    ("ORDER_STEP_SCAN", ORDER_STEP_SCAN),
    ("ORDER_STEP_SCATTER", ORDER_STEP_SCATTER),
    ("ORDER_BINDING_RAYS", ORDER_BINDING_RAYS),
    ("ORDER_BINDING_BUCKETS", ORDER_BINDING_BUCKETS),
    ("ORDER_BINDING_LIST", ORDER_BINDING_LIST),
    ("BINDING_CAREFUL", BINDING_CAREFUL),
    ("RQ_BINDING_SCENE", RQ_BINDING_SCENE),
    ("RQ_BINDING_PRIM_IDS", RQ_BINDING_PRIM_IDS),
    ("RQ_BINDING_RAYS", RQ_BINDING_RAYS),
    ("RQ_BINDING_HITS", RQ_BINDING_HITS),
    ("CAREFUL_HEADER_WORDS", CAREFUL_HEADER_WORDS),
    ("CAREFUL_COUNT", CAREFUL_COUNT),
    ("CAREFUL_MAX_GROUPS", CAREFUL_MAX_GROUPS),
    ("RASTER_VERTEX_BINDING", RASTER_VERTEX_BINDING),
    ("RASTER_LOCATION_POSITION", RASTER_LOCATION_POSITION),
    ("RASTER_LOCATION_PRIM", RASTER_LOCATION_PRIM),
    ("RASTER_LOCATION_VISIBILITY", RASTER_LOCATION_VISIBILITY),
    ("PROBE_BINDING_RAYS", PROBE_BINDING_RAYS),
    ("PROBE_BINDING_HITS", PROBE_BINDING_HITS),
    ("PROBE_BINDING_NODES", PROBE_BINDING_NODES),
    ("PROBE_BINDING_RASTER_VIEWS", PROBE_BINDING_RASTER_VIEWS),
    ("PROBE_BINDING_WORDS", PROBE_BINDING_WORDS),
    ("PASS_ONE", PASS_ONE),
    ("PASS_FAST", PASS_FAST),
    ("PASS_CAREFUL", PASS_CAREFUL),
    ("COUNTER_NODES", COUNTER_NODES),
    ("COUNTER_LEAVES", COUNTER_LEAVES),
    ("COUNTER_TRIANGLES", COUNTER_TRIANGLES),
    ("COUNTER_RESTARTS", COUNTER_RESTARTS),
    ("COUNTER_STEPS", COUNTER_STEPS),
    ("COUNTER_DROPS", COUNTER_DROPS),
    ("COUNTERS_PER_RAY", COUNTERS_PER_RAY),
];
