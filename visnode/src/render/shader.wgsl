// The visualization node's two pipelines: geometry (the object's triangles) and boards (a
// displaced proxy grid, textured per pixel from the board's maps). Both shade the same way, so
// a board seen from its creation direction matches its geometry.

struct Draw {
    // Local coordinates to clip space, camera-relative (no large numbers in f32).
    clip_from_local: mat4x4<f32>,
    // x: cross-fade amount in [0, 1]; y: 1 for the outgoing board of a cross-fade;
    // z: 1 for a flat board (billboard); w: 1 where the draw is an object the benchmark
    // measures (written to the object mask), 0 for terrain and other never-replaced objects.
    params: vec4<f32>,
    // rgb: tint colour, a: tint strength (0 = none).
    tint: vec4<f32>,
    // xyz: the eye in the draw's local coordinates (boards: map coordinates; octahedral
    // impostors: relative to the centre).
    eye: vec4<f32>,
};
// One entry per draw of the frame, bound once: a draw picks its entry by its instance
// index, which the vertex stage hands the fragment stage as `draw_index`, so no draw sets a
// bind group of its own for it.
@group(0) @binding(0) var<storage, read> draws: array<Draw>;
// This draw's entry, set first thing by every entry point that reads it.
var<private> draw: Draw;

const LIGHT: vec3<f32> = vec3<f32>(0.3578, 0.8050, 0.4732);

fn shade(color: vec3<f32>, normal: vec3<f32>) -> vec4<f32> {
    let lit = color * (0.4 + 0.6 * max(dot(normal, LIGHT), 0.0));
    return vec4<f32>(mix(lit, draw.tint.rgb, draw.tint.a), 1.0);
}

// Colour, and the object mask where the target has one (a window's pipelines have no mask
// target, and wgpu ignores an output without one).
struct Fragment {
    @location(0) color: vec4<f32>,
    @location(1) object: f32,
};

// ---- geometry ----

struct GeometryVaryings {
    @builtin(position) clip: vec4<f32>,
    @location(0) color: vec4<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) @interpolate(flat) draw_index: u32,
};

fn geometry_varyings(position: vec3<f32>, normal: vec4<f32>, color: vec4<f32>, instance: u32) -> GeometryVaryings {
    draw = draws[instance];
    var out: GeometryVaryings;
    out.clip = draw.clip_from_local * vec4<f32>(position, 1.0);
    out.color = color;
    out.normal = normal.xyz;
    out.draw_index = instance;
    return out;
}

@vertex
fn geometry_vs(
    @location(0) position: vec3<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) color: vec4<f32>,
    @builtin(instance_index) instance: u32,
) -> GeometryVaryings {
    return geometry_varyings(position, normal, color, instance);
}

// Two-sided, like the maps: the normal faces the viewer.
fn facing_normal(normal: vec3<f32>, front: bool) -> vec3<f32> {
    let n = normalize(normal);
    return select(-n, n, front);
}

@fragment
fn geometry_fs(in: GeometryVaryings, @builtin(front_facing) front: bool) -> Fragment {
    draw = draws[in.draw_index];
    return Fragment(shade(in.color.rgb, facing_normal(in.normal, front)), draw.params.w);
}

// ---- coarser levels of detail ----
// Where a simplifier folds a thin part onto one plane (the plant's walls from afar), its
// triangles keep corners of faces at right angles to them, and smooth shading would smear
// one face's light across another; so a level's pixel whose normal is more than 60° off its
// triangle's takes the triangle's, as the worker's levels' corners do
// (`backend::simplify::compact`). Between 30° and 60° it turns part of the way: cut at 60°
// alone, the part of a folded triangle still within 60° kept a bright wedge of the smear
// (plant stills, whole frame: 27.74 against 27.88 dB with the blend; the dragon's 32.28
// against 32.35); within 30° a level's smooth shading is left as it is.
// Per pixel, not with vertex copies: copies in the LOD chain's buffers slowed the plant's
// relief orbit on lavapipe (README). Full meshes skip it (their crease-aware normals stay
// within 60° of each face): the one more varying made geometry only's dragon frames about a
// tenth slower on lavapipe.

// The cosines of 60° (turned all the way) and 30° (not at all).
const TURN_COSINE: f32 = 0.5;
const BLEND_COSINE: f32 = 0.866;

struct LevelVaryings {
    @builtin(position) clip: vec4<f32>,
    @location(0) color: vec4<f32>,
    @location(1) normal: vec3<f32>,
    // The point in local coordinates: its screen derivatives give the triangle's plane.
    @location(2) local: vec3<f32>,
    @location(3) @interpolate(flat) draw_index: u32,
};

@vertex
fn level_vs(
    @location(0) position: vec3<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) color: vec4<f32>,
    @builtin(instance_index) instance: u32,
) -> LevelVaryings {
    let geometry = geometry_varyings(position, normal, color, instance);
    return LevelVaryings(geometry.clip, geometry.color, geometry.normal, position, instance);
}

@fragment
fn level_fs(in: LevelVaryings, @builtin(front_facing) front: bool) -> Fragment {
    draw = draws[in.draw_index];
    // The triangle's normal towards the viewer (screen x right and y down in a
    // right-handed view).
    let across = cross(dpdy(in.local), dpdx(in.local));
    var n = facing_normal(in.normal, front);
    let face_length = length(across);
    if (face_length > 0.0) {
        let face = across / face_length;
        let turn = clamp((BLEND_COSINE - dot(n, face)) / (BLEND_COSINE - TURN_COSINE), 0.0, 1.0);
        n = normalize(mix(n, face, turn));
    }
    return Fragment(shade(in.color.rgb, n), draw.params.w);
}

// ---- boards ----

// Soft silhouettes (`--soft-edges`): a board's edge pixels are blended over what is drawn by
// their coverage, down to SOFT_EDGE_CUT (below it nothing is drawn, so that faint edges do
// not hide what is behind them in the depth buffer), instead of cut at one half.
override SOFT_EDGES: bool = false;
const SOFT_EDGE_CUT: f32 = 0.25;

// One texture of three RGBA8 layers (`MAP_LAYERS`): colour with the stencil in alpha; the
// normal biased into [0, 1], zero where uncovered; the depth's f32 bytes.
@group(1) @binding(0) var board_maps: texture_2d_array<f32>;
// Bilinear, clamped to the edge: colour and normal only (depth is read per texel).
@group(1) @binding(1) var board_sampler: sampler;

// Exact: each byte comes back from its unorm value by pack4x8unorm's rounding.
fn map_depth(texel: vec2<i32>) -> f32 {
    return bitcast<f32>(pack4x8unorm(textureLoad(board_maps, texel, 2, 0)));
}

struct BoardVaryings {
    @builtin(position) clip: vec4<f32>,
    // The grid's point in map coordinates: x, y in [-1, 1], z the view depth.
    @location(0) map: vec3<f32>,
    @location(1) @interpolate(flat) draw_index: u32,
};

@vertex
fn board_vs(@location(0) position: vec3<f32>, @builtin(instance_index) instance: u32) -> BoardVaryings {
    draw = draws[instance];
    var out: BoardVaryings;
    out.clip = draw.clip_from_local * vec4<f32>(position, 1.0);
    out.map = position;
    out.draw_index = instance;
    return out;
}

struct BoardFragment {
    @location(0) color: vec4<f32>,
    @location(1) object: f32,
    @builtin(frag_depth) depth: f32,
};

// The same without a depth of its own: the displaced grid's depth is written (`BoardDepth`).
struct GridDepthFragment {
    @location(0) color: vec4<f32>,
    @location(1) object: f32,
};

// 4x4 ordered dither: the cross-fade keeps complementary pixel sets of the two boards.
fn bayer(pixel: vec2<f32>) -> f32 {
    let m = array<f32, 16>(0.0, 8.0, 2.0, 10.0, 12.0, 4.0, 14.0, 6.0, 3.0, 11.0, 1.0, 9.0, 15.0, 7.0, 13.0, 5.0);
    let p = vec2<u32>(pixel) % vec2<u32>(4u, 4u);
    return (m[p.y * 4u + p.x] + 0.5) / 16.0;
}

// The texel under map point `p` (x, y in [-1, 1], y up).
fn board_texel(p: vec2<f32>, size: vec2<i32>) -> vec2<i32> {
    let uv = vec2<f32>(p.x + 1.0, 1.0 - p.y) * 0.5;
    return clamp(vec2<i32>(floor(uv * vec2<f32>(size))), vec2<i32>(0, 0), size - vec2<i32>(1, 1));
}

// One step of the per-pixel parallax correction (see board_fs): from map point `p`, the
// point of the pixel's ray (from `eye` along `ray`, map coordinates) at the depth read at
// `p`; `p` itself where that texel is uncovered (the ray leaves the silhouette there).
fn parallax_step(p: vec2<f32>, eye: vec3<f32>, ray: vec3<f32>, size: vec2<i32>) -> vec2<f32> {
    let z = map_depth(board_texel(p, size));
    return select(eye.xy + ray.xy * ((z - eye.z) / ray.z), p, z > 1.5);
}

// A board's pixel with the depth read from its depth map (`BoardDepth::Pixel`).
@fragment
fn board_fs(in: BoardVaryings) -> BoardFragment {
    draw = draws[in.draw_index];
    return board_pixel(in);
}

// A board's pixel at the grid's depth (`BoardDepth::Grid`): without a depth output the
// rasteriser may test depth before shading, so pixels behind nearer surfaces cost nothing.
@fragment
fn board_grid_depth_fs(in: BoardVaryings) -> GridDepthFragment {
    draw = draws[in.draw_index];
    let pixel = board_pixel(in);
    return GridDepthFragment(pixel.color, pixel.object);
}

fn board_pixel(in: BoardVaryings) -> BoardFragment {
    let size = vec2<i32>(textureDimensions(board_maps));
    // The grid places the maps on screen only roughly: inside a cell, and where a corner
    // off the silhouette took a neighbour's depth, its surface is not the object's, and in
    // perspective a texel off that surface lands beside its place (boards came out up to
    // three pixels too wide at a 32-cell grid). So the pixel's own ray is followed to the
    // depth map: from the grid's point, move along the ray to the depth read there, a few
    // times (a fixed point: parallax mapping's iteration). `draw.eye` is the eye in map
    // coordinates.
    // Straight-line code: the same steps as a loop with a break, with a discard for points
    // off the map before the stencil test, made the forest's frames 2.5 times slower on
    // lavapipe (0.32 against 0.83 s). Flat boards (billboards) do not move (`draw.eye.w`
    // is 0 for them).
    let eye = draw.eye.xyz;
    let ray = in.map - eye;
    var p = in.map.xy;
    p = parallax_step(p, eye, ray, size);
    p = parallax_step(p, eye, ray, size);
    p = parallax_step(p, eye, ray, size);
    p = mix(in.map.xy, p, draw.eye.w);
    let texel = board_texel(p, size);
    // The stencil: outside the silhouette nothing is drawn. The silhouette runs where the
    // bilinear coverage crosses one half, between texel centres, not along the nearest
    // texel's staircase; a texel just outside holds its covered neighbours' depth
    // (`board::extend_depth_one_texel`).
    let filtered = board_bilinear(p);
    if (filtered.coverage < select(0.5, SOFT_EDGE_CUT, SOFT_EDGES)) {
        discard;
    }
    let keep_new = bayer(in.clip.xy) < draw.params.x;
    if (keep_new == (draw.params.y > 0.5)) {
        discard;
    }
    var z = map_depth(texel);
    if (z > 1.5) {
        discard;
    }
    if (draw.params.z > 0.5) {
        z = 0.0;
    }
    // Per-pixel depth from the depth map: the proxy grid only places the texels on screen.
    let clip = draw.clip_from_local * vec4<f32>(p, z, 1.0);
    var out: BoardFragment;
    out.depth = clamp(clip.z / clip.w, 0.0, 1.0);
    out.color = shade(filtered.color, normalize(filtered.normal + vec3<f32>(0.0, 0.0, 1e-6)));
    if (SOFT_EDGES) {
        // The bilinear coverage is about the share of the pixel the object covers; blended
        // by it, an edge pixel's error is smaller than cut all or nothing either way.
        out.color.a = filtered.coverage;
    }
    out.object = draw.params.w;
    return out;
}

struct BoardSample {
    color: vec3<f32>,
    normal: vec3<f32>,
    // The share of the four texels around the point that are covered, bilinearly weighted.
    coverage: f32,
};

// Colour and normal at map point `p`, bilinear over the texels around it that are covered,
// so nothing from outside the silhouette bleeds into its edge: uncovered texels hold zero
// colour, alpha and normal, so the filtered colour over its alpha is the covered texels'
// mean, and the normal is normalised anyway. A board is drawn at about a texel a pixel but
// not on the pixel grid, and the nearest texel alone shifts shading by up to half a texel.
// The sampler's filtering, not four loads in a loop: on lavapipe the loop took the forest's
// frames from 0.34 to 0.85 s.
fn board_bilinear(p: vec2<f32>) -> BoardSample {
    let uv = vec2<f32>(p.x + 1.0, 1.0 - p.y) * 0.5;
    let c = textureSampleLevel(board_maps, board_sampler, uv, 0, 0.0);
    let n = textureSampleLevel(board_maps, board_sampler, uv, 1, 0.0).xyz;
    let covered = max(c.a, 1e-6);
    return BoardSample(c.rgb / covered, n / covered * 2.0 - 1.0, c.a);
}

// ---- board wireframes (debug view) ----

@fragment
fn wire_fs(in: BoardVaryings) -> Fragment {
    // The mask is not written by this pipeline (its write mask is empty).
    return Fragment(vec4<f32>(1.0, 0.85, 0.1, 1.0), 0.0);
}

// ---- octahedral impostors (`--impostor octahedral`) ----
// An atlas's maps as three plain textures (see `atlas_layout`).
@group(1) @binding(2) var atlas_depth: texture_2d<f32>;
@group(1) @binding(3) var atlas_color: texture_2d<f32>;
@group(1) @binding(4) var atlas_normal: texture_2d<f32>;

// One camera-facing quad per object; the board textures hold an atlas of `views x views`
// baked views. params: x radius, y views per side, z view side in texels, w object mask.
// `draw.eye` is the eye relative to the object's centre (the draw's local origin).

fn sign_nz(x: f32) -> f32 {
    return select(-1.0, 1.0, x >= 0.0);
}

// Octahedral map of the sphere, y up (the same as `octahedral::encode` and `decode`).
fn oct_encode(d: vec3<f32>) -> vec2<f32> {
    let n = d / (abs(d.x) + abs(d.y) + abs(d.z));
    if (n.y < 0.0) {
        return vec2<f32>((1.0 - abs(n.z)) * sign_nz(n.x), (1.0 - abs(n.x)) * sign_nz(n.z));
    }
    return n.xz;
}

fn oct_decode(p: vec2<f32>) -> vec3<f32> {
    let y = 1.0 - abs(p.x) - abs(p.y);
    var xz = p;
    if (y < 0.0) {
        xz = vec2<f32>((1.0 - abs(p.y)) * sign_nz(p.x), (1.0 - abs(p.x)) * sign_nz(p.y));
    }
    return normalize(vec3<f32>(xz.x, y, xz.y));
}

// The axes a board seen along `forward` has (`backend::Basis::new`).
fn basis_right(forward: vec3<f32>) -> vec3<f32> {
    var hint = vec3<f32>(0.0, 1.0, 0.0);
    if (abs(forward.y) >= 0.99) {
        hint = vec3<f32>(0.0, 0.0, 1.0);
    }
    return normalize(cross(forward, hint));
}

struct OctaVaryings {
    @builtin(position) clip: vec4<f32>,
    @location(0) local: vec3<f32>,
    @location(1) @interpolate(flat) draw_index: u32,
};

@vertex
fn octa_vs(@location(0) corner: vec3<f32>, @builtin(instance_index) instance: u32) -> OctaVaryings {
    draw = draws[instance];
    let radius = draw.params.x;
    let eye = draw.eye.xyz;
    let distance = length(eye);
    let forward = -eye / distance;
    let right = basis_right(forward);
    let up = cross(right, forward);
    // The sphere's silhouette on the plane through its centre is the tangent cone's circle.
    let half = radius * distance / sqrt(max(distance * distance - radius * radius, radius * radius * 1e-4));
    var out: OctaVaryings;
    out.local = (right * corner.x + up * corner.y) * half;
    out.clip = draw.clip_from_local * vec4<f32>(out.local, 1.0);
    out.draw_index = instance;
    return out;
}

// The atlas texel of map point `uv` ([-1, 1]², y up) in view `cell`.
fn atlas_texel(cell: vec2<i32>, uv: vec2<f32>) -> vec2<i32> {
    let s = i32(draw.params.z);
    let m = vec2<f32>(uv.x + 1.0, 1.0 - uv.y) * 0.5;
    let inner = clamp(vec2<i32>(floor(m * f32(s))), vec2<i32>(0, 0), vec2<i32>(s - 1, s - 1));
    return cell * s + inner;
}

struct ViewSample {
    color: vec4<f32>,
    normal: vec3<f32>,
    point: vec3<f32>,
};

// What baked view `cell` shows along the ray from `eye` in direction `ray`: the ray meets
// the view's plane through the centre, steps once to the depth the view has there
// (parallax), and reads colour, normal and the surface point at the stepped position.
fn sample_view(cell: vec2<i32>, eye: vec3<f32>, ray: vec3<f32>) -> ViewSample {
    let radius = draw.params.x;
    let views = draw.params.y;
    let forward = -oct_decode(vec2<f32>(cell) / (views - 1.0) * 2.0 - 1.0);
    let right = basis_right(forward);
    let up = cross(right, forward);
    let along = dot(ray, forward);
    var out: ViewSample;
    out.color = vec4<f32>(0.0);
    out.normal = vec3<f32>(0.0);
    out.point = vec3<f32>(0.0);
    if (along <= 1e-4) {
        return out;
    }
    var p = eye + ray * (-dot(eye, forward) / along);
    var uv = vec2<f32>(dot(p, right), dot(p, up)) / radius;
    let z0 = textureLoad(atlas_depth, atlas_texel(cell, uv), 0).r;
    if (z0 < 1.5) {
        p = eye + ray * ((z0 * radius - dot(eye, forward)) / along);
        uv = vec2<f32>(dot(p, right), dot(p, up)) / radius;
    }
    if (any(abs(uv) > vec2<f32>(1.0))) {
        return out;
    }
    let texel = atlas_texel(cell, uv);
    let z = textureLoad(atlas_depth, texel, 0).r;
    out.color = textureLoad(atlas_color, texel, 0);
    if (out.color.a < 0.5 || z > 1.5) {
        out.color = vec4<f32>(0.0);
        return out;
    }
    out.normal = textureLoad(atlas_normal, texel, 0).xyz;
    out.point = (right * uv.x + up * uv.y + forward * z) * radius;
    return out;
}

@fragment
fn octa_fs(in: OctaVaryings) -> BoardFragment {
    draw = draws[in.draw_index];
    let eye = draw.eye.xyz;
    let ray = normalize(in.local - eye);
    let views = draw.params.y;
    // The three baked views around the view direction, with barycentric weights in the grid.
    let g = (oct_encode(normalize(eye)) * 0.5 + 0.5) * (views - 1.0);
    let base = clamp(floor(g), vec2<f32>(0.0), vec2<f32>(views - 2.0));
    let f = clamp(g - base, vec2<f32>(0.0), vec2<f32>(1.0));
    let b = vec2<i32>(base);
    var cells = array<vec2<i32>, 3>(b, b + vec2<i32>(1, 0), b + vec2<i32>(0, 1));
    var weights = vec3<f32>(1.0 - f.x - f.y, f.x, f.y);
    if (f.x + f.y > 1.0) {
        cells = array<vec2<i32>, 3>(b + vec2<i32>(1, 1), b + vec2<i32>(0, 1), b + vec2<i32>(1, 0));
        weights = vec3<f32>(f.x + f.y - 1.0, 1.0 - f.x, 1.0 - f.y);
    }
    var color = vec3<f32>(0.0);
    var normal = vec3<f32>(0.0);
    var point = vec3<f32>(0.0);
    var coverage = 0.0;
    for (var k = 0; k < 3; k++) {
        let s = sample_view(cells[k], eye, ray);
        let w = weights[k] * s.color.a;
        color += w * s.color.rgb;
        normal += w * s.normal;
        point += w * s.point;
        coverage += w;
    }
    // The silhouette: where the views together cover less than half, nothing is drawn.
    if (coverage < 0.5) {
        discard;
    }
    let clip = draw.clip_from_local * vec4<f32>(point / coverage, 1.0);
    var out: BoardFragment;
    out.depth = clamp(clip.z / clip.w, 0.0, 1.0);
    out.color = shade(color / coverage, normalize(normal + vec3<f32>(0.0, 0.0, 1e-6)));
    out.object = draw.params.w;
    return out;
}
