// The visualization node's two pipelines: geometry (the object's triangles) and boards (a
// displaced proxy grid, textured per pixel from the board's maps). Both shade the same way, so
// a board seen from its creation direction matches its geometry.

struct Draw {
    // Local coordinates to clip space, camera-relative (no large numbers in f32).
    clip_from_local: mat4x4<f32>,
    // x: cross-fade amount in [0, 1]; y: 1 for the outgoing board of a cross-fade;
    // z: 1 for a flat board (billboard); w: unused.
    params: vec4<f32>,
    // rgb: tint colour, a: tint strength (0 = none).
    tint: vec4<f32>,
};
@group(0) @binding(0) var<uniform> draw: Draw;

const LIGHT: vec3<f32> = vec3<f32>(0.3578, 0.8050, 0.4732);

fn shade(color: vec3<f32>, normal: vec3<f32>) -> vec4<f32> {
    let lit = color * (0.4 + 0.6 * max(dot(normal, LIGHT), 0.0));
    return vec4<f32>(mix(lit, draw.tint.rgb, draw.tint.a), 1.0);
}

// ---- geometry ----

struct GeometryVaryings {
    @builtin(position) clip: vec4<f32>,
    @location(0) color: vec4<f32>,
    @location(1) normal: vec3<f32>,
};

@vertex
fn geometry_vs(
    @location(0) position: vec3<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) color: vec4<f32>,
) -> GeometryVaryings {
    var out: GeometryVaryings;
    out.clip = draw.clip_from_local * vec4<f32>(position, 1.0);
    out.color = color;
    out.normal = normal.xyz;
    return out;
}

@fragment
fn geometry_fs(in: GeometryVaryings, @builtin(front_facing) front: bool) -> @location(0) vec4<f32> {
    // Two-sided, like the maps: the normal faces the viewer.
    var n = normalize(in.normal);
    if (!front) {
        n = -n;
    }
    return shade(in.color.rgb, n);
}

// ---- boards ----

@group(1) @binding(0) var board_depth: texture_2d<f32>;
@group(1) @binding(1) var board_color: texture_2d<f32>;
@group(1) @binding(2) var board_normal: texture_2d<f32>;

struct BoardVaryings {
    @builtin(position) clip: vec4<f32>,
    @location(0) map: vec2<f32>,
};

@vertex
fn board_vs(@location(0) position: vec3<f32>) -> BoardVaryings {
    var out: BoardVaryings;
    out.clip = draw.clip_from_local * vec4<f32>(position, 1.0);
    out.map = position.xy;
    return out;
}

struct BoardFragment {
    @location(0) color: vec4<f32>,
    @builtin(frag_depth) depth: f32,
};

// 4x4 ordered dither: the cross-fade keeps complementary pixel sets of the two boards.
fn bayer(pixel: vec2<f32>) -> f32 {
    let m = array<f32, 16>(0.0, 8.0, 2.0, 10.0, 12.0, 4.0, 14.0, 6.0, 3.0, 11.0, 1.0, 9.0, 15.0, 7.0, 13.0, 5.0);
    let p = vec2<u32>(pixel) % vec2<u32>(4u, 4u);
    return (m[p.y * 4u + p.x] + 0.5) / 16.0;
}

@fragment
fn board_fs(in: BoardVaryings) -> BoardFragment {
    let size = vec2<i32>(textureDimensions(board_color));
    let uv = vec2<f32>(in.map.x + 1.0, 1.0 - in.map.y) * 0.5;
    let texel = clamp(vec2<i32>(floor(uv * vec2<f32>(size))), vec2<i32>(0, 0), size - vec2<i32>(1, 1));
    let color = textureLoad(board_color, texel, 0);
    // The stencil: outside the silhouette nothing is drawn.
    if (color.a < 0.5) {
        discard;
    }
    let keep_new = bayer(in.clip.xy) < draw.params.x;
    if (keep_new == (draw.params.y > 0.5)) {
        discard;
    }
    var z = textureLoad(board_depth, texel, 0).r;
    if (draw.params.z > 0.5) {
        z = 0.0;
    }
    // Per-pixel depth from the depth map: the proxy grid only places the texels on screen.
    let clip = draw.clip_from_local * vec4<f32>(in.map, z, 1.0);
    var out: BoardFragment;
    out.depth = clamp(clip.z / clip.w, 0.0, 1.0);
    let n = textureLoad(board_normal, texel, 0).xyz;
    out.color = shade(color.rgb, normalize(n + vec3<f32>(0.0, 0.0, 1e-6)));
    return out;
}

// ---- board wireframes (debug view) ----

@fragment
fn wire_fs(in: BoardVaryings) -> @location(0) vec4<f32> {
    return vec4<f32>(1.0, 0.85, 0.1, 1.0);
}
