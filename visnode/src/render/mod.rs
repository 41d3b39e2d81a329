//! The wgpu renderer: geometry and reliefboards into a colour and depth target, one code path
//! on a GPU and on Mesa's CPU Vulkan driver (lavapipe).
//!
//! Everything is drawn relative to the camera, so f32 on the GPU keeps its precision in
//! scenes far from the origin. Per-draw data (a matrix, cross-fade and tint) lives in one
//! uniform buffer with dynamic offsets, written once per frame.

use std::num::NonZeroU64;
use std::time::{Duration, Instant};

use glam::{DMat4, DVec3, Mat4};
use wgpu::util::DeviceExt;

use crate::board::{BoardData, snorm};
use crate::camera::View;

/// Colour of the empty sky, in both the frame and the reference.
pub const CLEAR_COLOR: [f64; 4] = [0.62, 0.74, 0.88, 1.0];
/// Format of the offscreen target.
pub const OFFSCREEN_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;
const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
use crate::board::MAP_LAYERS;
/// Texels of a board's maps written per step of its upload (a band of rows): a 256-pixel
/// board in one band, a 1024-pixel one (12 MiB, 9-50 ms to write on lavapipe) in 16, as many
/// a frame as its upload budget takes, so no frame waits for a whole large board.
const UPLOAD_BAND_TEXELS: u32 = 1 << 16;

/// Format of the offscreen object mask: 1 where a measured object was drawn last.
const MASK_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R8Unorm;
/// Bytes of one draw's entry in the frame's storage buffer of draws (the WGSL array's stride).
const DRAW_STRIDE: u64 = std::mem::size_of::<DrawUniform>() as u64;

/// Why the renderer cannot run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RenderError {
    /// No adapter: no GPU and no software Vulkan driver.
    #[error(
        "no wgpu adapter: {0} (on a machine without a GPU install Mesa's CPU Vulkan driver: apt-get install mesa-vulkan-drivers libvulkan1)"
    )]
    NoAdapter(String),
    /// The device failed.
    #[error("wgpu device error: {0}")]
    Device(String),
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GeometryVertex {
    position: [f32; 3],
    normal: [i8; 4],
    color: [u8; 4],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct DrawUniform {
    clip_from_local: [f32; 16],
    params: [f32; 4],
    tint: [f32; 4],
    eye: [f32; 4],
}

/// An object's triangles on the GPU.
pub struct Mesh {
    vertices: wgpu::Buffer,
    /// Index buffers from the full mesh (level 0) to the coarsest level of detail, with their
    /// triangle counts; all index the same vertices.
    levels: Vec<(wgpu::Buffer, u64)>,
    origin: DVec3,
    /// Triangles of the full mesh.
    pub triangles: u64,
}

impl Mesh {
    /// Levels of detail held (1: the full mesh only).
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// Triangles of `level` (the coarsest when past the last).
    pub fn level_triangles(&self, level: usize) -> u64 {
        self.levels[level.min(self.levels.len() - 1)].1
    }

    /// GPU bytes of the index buffers of the coarser levels (what a LOD chain adds).
    pub fn lod_bytes(&self) -> u64 {
        self.levels.iter().skip(1).map(|(_, t)| t * 12).sum()
    }
}

/// A board on the GPU: its maps as one layered texture (one allocation a board, since each
/// is a search of the GPU allocator's free list, which grows with the boards held). Its proxy
/// grid stays here and is copied each frame it is drawn into the frame's one grid buffer
/// with the other boards' ([`Renderer::write_board_grids`]).
pub struct GpuBoard {
    bind_group: wgpu::BindGroup,
    grid_vertices: Vec<[f32; 3]>,
    grid_indices: Vec<u32>,
    local_to_world: (DVec3, glam::DMat3),
    flat: bool,
    /// GPU bytes held: the maps' texture.
    pub bytes: usize,
}

/// A board on its way to the GPU: drawn once every band of its maps is written.
pub struct BoardUpload {
    board: GpuBoard,
    texture: wgpu::Texture,
    rows_written: u32,
}

impl GpuBoard {
    /// Triangles of the proxy grid.
    pub fn triangles(&self) -> u64 {
        self.grid_indices.len() as u64 / 3
    }
}

impl BoardUpload {
    /// The board, ready to draw (call after its last band).
    pub fn finish(self) -> GpuBoard {
        self.board
    }
}

/// An object's baked octahedral views on the GPU (`--impostor octahedral`).
pub struct GpuOctahedral {
    bind_group: wgpu::BindGroup,
    center: DVec3,
    radius: f64,
    params: crate::far_field::octahedral::OctahedralParams,
    /// GPU bytes held (the atlas textures).
    pub bytes: u64,
}

/// One draw of a frame.
#[derive(Clone, Copy)]
pub enum DrawItem<'a> {
    /// An object's geometry.
    Geometry {
        /// The mesh.
        mesh: &'a Mesh,
        /// The level of detail drawn: 0 is the full mesh (see [`Mesh::levels`]).
        level: usize,
        /// Whether its pixels count as object pixels in the benchmark (false for terrain and
        /// other objects no impostor ever replaces).
        object: bool,
        /// Tint colour and strength (strength 0: none).
        tint: [f32; 4],
    },
    /// A board.
    Board {
        /// The board.
        board: &'a GpuBoard,
        /// Cross-fade progress: 1 shows all of it.
        fade: f32,
        /// The outgoing board of a cross-fade: shows the complement of `fade`.
        outgoing: bool,
        /// Tint colour and strength.
        tint: [f32; 4],
    },
    /// An object's octahedral impostor: one camera-facing quad.
    Octahedral {
        /// The baked views.
        impostor: &'a GpuOctahedral,
    },
}

/// Time a frame took.
#[derive(Debug, Clone, Copy, Default, serde::Serialize)]
pub struct FrameTiming {
    /// Building and submitting the commands.
    pub cpu_ms: f64,
    /// From submission until the GPU finished.
    pub gpu_ms: f64,
    /// Triangles submitted.
    pub triangles: u64,
}

/// Whether boards' silhouettes are blended by their coverage unless asked otherwise
/// (`--soft-edges`): on lavapipe +0.5 dB over the forest's object pixels at the same frame
/// time (README, "Soft silhouettes").
pub const DEFAULT_SOFT_EDGES: bool = true;

/// Where a board's pixels take their depth from (`--board-depth`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum BoardDepth {
    /// The depth map, read per pixel: exact where a board meets other surfaces, but a
    /// fragment shader that writes depth runs for every pixel the board covers, hidden ones
    /// too (the depth test can only follow it).
    Pixel,
    /// The displaced grid's own depth (Süß's reliefboard): the depth test runs before the
    /// shader, so hidden pixels cost nothing; where a board meets a surface, the line may
    /// move within a grid cell (`--board-cell-pixels`). The default: on lavapipe it took
    /// 12-21% off relief's frame time on the forest and plant with no loss of image quality
    /// (README), and the depth-order test swaps no more pixels than with `Pixel`.
    #[default]
    Grid,
}

/// The device, the pipelines and an offscreen target.
pub struct Renderer {
    device: wgpu::Device,
    queue: wgpu::Queue,
    /// Full meshes.
    geometry_pipeline: wgpu::RenderPipeline,
    /// Coarser levels of detail, whose folded corners are lit by their triangles (the
    /// shader's `level_vs` and `level_fs`).
    level_pipeline: wgpu::RenderPipeline,
    board_pipeline: wgpu::RenderPipeline,
    /// Boards at their grid's depth ([`BoardDepth::Grid`]).
    board_grid_depth_pipeline: wgpu::RenderPipeline,
    /// Where boards take their depth from.
    pub board_depth: BoardDepth,
    /// [`Renderer::board_pipeline`] and [`Renderer::board_grid_depth_pipeline`] with soft
    /// silhouettes (`--soft-edges`).
    soft_board_pipelines: (wgpu::RenderPipeline, wgpu::RenderPipeline),
    /// Blend a board's silhouette by its coverage instead of cutting it at one half.
    pub soft_edges: bool,
    octahedral_pipeline: wgpu::RenderPipeline,
    /// A unit quad (corners at ±1), drawn camera-facing for octahedral impostors.
    quad: (wgpu::Buffer, wgpu::Buffer),
    /// Board proxy grids as lines, where the device can draw lines from triangles.
    wire_pipeline: Option<wgpu::RenderPipeline>,
    /// Draw board proxy grids as lines over the frame.
    pub wireframe: bool,
    board_layout: wgpu::BindGroupLayout,
    /// An octahedral atlas's three textures (depth, colour, normal).
    atlas_layout: wgpu::BindGroupLayout,
    /// Bilinear filtering of boards' colour and normal maps.
    board_sampler: wgpu::Sampler,
    draw_layout: wgpu::BindGroupLayout,
    draw_buffer: wgpu::Buffer,
    draw_bind_group: wgpu::BindGroup,
    draw_capacity: u64,
    /// The proxy grids of the frame's boards: all vertices, then all indices
    /// ([`Renderer::write_board_grids`]).
    board_grids: wgpu::Buffer,
    /// Where each of the frame's draws finds its board's grid in `board_grids`.
    board_grid_at: Vec<BoardGridAt>,
    /// Where the indices start in `board_grids` (0: no board this frame).
    board_grid_index_offset: u64,
    target: Target,
    /// A second offscreen target, so the frame before the last can still be read back.
    spare: Option<Target>,
    /// Whether targets carry an object mask (offscreen renderers; a window's do not).
    mask: bool,
    /// Adapter name and backend, for reports.
    pub adapter: String,
}

struct Target {
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    mask: Option<(wgpu::Texture, wgpu::TextureView)>,
    depth_view: wgpu::TextureView,
    size: [u32; 2],
}

impl Renderer {
    /// Opens the first adapter (a GPU, or lavapipe) with an offscreen target of `resolution`.
    pub fn new(resolution: [u32; 2]) -> Result<Renderer, RenderError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pick_adapter(&instance, None)?;
        let limits = adapter.limits();
        if resolution[0] > limits.max_texture_dimension_2d
            || resolution[1] > limits.max_texture_dimension_2d
        {
            return Err(RenderError::Device(format!(
                "resolution {}x{} exceeds the adapter's largest texture side {}",
                resolution[0], resolution[1], limits.max_texture_dimension_2d
            )));
        }
        let (device, queue, name) = open_device(&adapter)?;
        Ok(Self::build(
            device,
            queue,
            OFFSCREEN_FORMAT,
            resolution,
            name,
            true,
        ))
    }

    /// A renderer on an existing device drawing into targets of `format` (a window's surface).
    pub fn with_device(
        device: wgpu::Device,
        queue: wgpu::Queue,
        format: wgpu::TextureFormat,
        resolution: [u32; 2],
        adapter: String,
    ) -> Renderer {
        Self::build(device, queue, format, resolution, adapter, false)
    }

    fn build(
        device: wgpu::Device,
        queue: wgpu::Queue,
        format: wgpu::TextureFormat,
        resolution: [u32; 2],
        adapter: String,
        mask: bool,
    ) -> Renderer {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("visnode"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shader.wgsl").into()),
        });
        let draw_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("draw"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX_FRAGMENT,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only: true },
                    has_dynamic_offset: false,
                    min_binding_size: NonZeroU64::new(DRAW_STRIDE),
                },
                count: None,
            }],
        });
        let texture_entry = |binding, filterable, view_dimension| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable },
                view_dimension,
                multisampled: false,
            },
            count: None,
        };
        // The maps: colour, normal and depth layers of one texture; the first two filtered.
        let board_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("board maps"),
            entries: &[
                texture_entry(0, true, wgpu::TextureViewDimension::D2Array),
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
            ],
        });
        let board_sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("board maps"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        // Octahedral atlases keep three plain textures: as layers of one texture (what boards
        // use) lavapipe drew the forest's atlases 35 times slower (2.7 s a frame, not 75 ms).
        let plain = |binding| texture_entry(binding, false, wgpu::TextureViewDimension::D2);
        let atlas_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("octahedral atlas"),
            entries: &[plain(2), plain(3), plain(4)],
        });
        let geometry_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("geometry"),
            bind_group_layouts: &[Some(&draw_layout)],
            immediate_size: 0,
        });
        let board_pipeline_layout =
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("board"),
                bind_group_layouts: &[Some(&draw_layout), Some(&board_layout)],
                immediate_size: 0,
            });
        let atlas_pipeline_layout =
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("octahedral impostor"),
                bind_group_layouts: &[Some(&draw_layout), Some(&atlas_layout)],
                immediate_size: 0,
            });
        let depth_stencil = Some(wgpu::DepthStencilState {
            format: DEPTH_FORMAT,
            depth_write_enabled: Some(true),
            // Reverse-Z: near is 1, far is 0 (see `camera::reverse_z_perspective`).
            depth_compare: Some(wgpu::CompareFunction::Greater),
            stencil: Default::default(),
            bias: Default::default(),
        });
        let geometry_attributes =
            wgpu::vertex_attr_array![0 => Float32x3, 1 => Snorm8x4, 2 => Unorm8x4];
        let board_attributes = wgpu::vertex_attr_array![0 => Float32x3];
        let pipeline = |label,
                        layout: &wgpu::PipelineLayout,
                        entry: (&str, &str),
                        stride,
                        attributes: &[wgpu::VertexAttribute],
                        lines: bool,
                        soft: bool| {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(label),
                layout: Some(layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some(entry.0),
                    compilation_options: Default::default(),
                    buffers: &[Some(wgpu::VertexBufferLayout {
                        array_stride: stride,
                        step_mode: wgpu::VertexStepMode::Vertex,
                        attributes,
                    })],
                },
                // Two-sided: scenes do not promise consistent winding.
                primitive: wgpu::PrimitiveState {
                    cull_mode: None,
                    polygon_mode: if lines {
                        wgpu::PolygonMode::Line
                    } else {
                        wgpu::PolygonMode::Fill
                    },
                    ..Default::default()
                },
                // Wireframes are a debug view: drawn over everything (x-ray), writing no depth.
                depth_stencil: depth_stencil.clone().map(|mut state| {
                    if lines {
                        state.depth_write_enabled = Some(false);
                        state.depth_compare = Some(wgpu::CompareFunction::Always);
                    }
                    state
                }),
                multisample: Default::default(),
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some(entry.1),
                    compilation_options: wgpu::PipelineCompilationOptions {
                        constants: if soft { &[("SOFT_EDGES", 1.0)] } else { &[] },
                        ..Default::default()
                    },
                    targets: &[
                        Some(wgpu::ColorTargetState {
                            format,
                            // Soft edges: the colour over what is drawn by the coverage;
                            // the target stays opaque.
                            blend: soft.then_some(wgpu::BlendState {
                                color: wgpu::BlendState::ALPHA_BLENDING.color,
                                alpha: wgpu::BlendComponent::OVER,
                            }),
                            write_mask: wgpu::ColorWrites::ALL,
                        }),
                        mask.then(|| wgpu::ColorTargetState {
                            format: MASK_FORMAT,
                            blend: None,
                            // Wireframes are an overlay, not an object.
                            write_mask: if lines {
                                wgpu::ColorWrites::empty()
                            } else {
                                wgpu::ColorWrites::ALL
                            },
                        }),
                    ],
                }),
                multiview_mask: None,
                cache: None,
            })
        };
        let geometry_pipeline = pipeline(
            "geometry",
            &geometry_layout,
            ("geometry_vs", "geometry_fs"),
            std::mem::size_of::<GeometryVertex>() as u64,
            &geometry_attributes,
            false,
            false,
        );
        let level_pipeline = pipeline(
            "level of detail",
            &geometry_layout,
            ("level_vs", "level_fs"),
            std::mem::size_of::<GeometryVertex>() as u64,
            &geometry_attributes,
            false,
            false,
        );
        let board_pipeline = pipeline(
            "board",
            &board_pipeline_layout,
            ("board_vs", "board_fs"),
            12,
            &board_attributes,
            false,
            false,
        );
        let board_grid_depth_pipeline = pipeline(
            "board at its grid's depth",
            &board_pipeline_layout,
            ("board_vs", "board_grid_depth_fs"),
            12,
            &board_attributes,
            false,
            false,
        );
        let soft_board_pipelines = (
            pipeline(
                "board, soft edges",
                &board_pipeline_layout,
                ("board_vs", "board_fs"),
                12,
                &board_attributes,
                false,
                true,
            ),
            pipeline(
                "board at its grid's depth, soft edges",
                &board_pipeline_layout,
                ("board_vs", "board_grid_depth_fs"),
                12,
                &board_attributes,
                false,
                true,
            ),
        );
        let octahedral_pipeline = pipeline(
            "octahedral impostor",
            &atlas_pipeline_layout,
            ("octa_vs", "octa_fs"),
            12,
            &board_attributes,
            false,
            false,
        );
        let quad = (
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("quad"),
                contents: bytemuck::cast_slice(&[
                    [-1.0f32, -1.0, 0.0],
                    [1.0, -1.0, 0.0],
                    [1.0, 1.0, 0.0],
                    [-1.0, 1.0, 0.0],
                ]),
                usage: wgpu::BufferUsages::VERTEX,
            }),
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("quad indices"),
                contents: bytemuck::cast_slice(&[0u32, 1, 2, 0, 2, 3]),
                usage: wgpu::BufferUsages::INDEX,
            }),
        );
        let wire_pipeline = device
            .features()
            .contains(wgpu::Features::POLYGON_MODE_LINE)
            .then(|| {
                pipeline(
                    "board wireframe",
                    &board_pipeline_layout,
                    ("board_vs", "wire_fs"),
                    12,
                    &board_attributes,
                    true,
                    false,
                )
            });
        let draw_capacity = 256;
        let (draw_buffer, draw_bind_group) = draw_buffer(&device, &draw_layout, draw_capacity);
        let board_grids = board_grid_buffer(&device, 0);
        let target = Target::new(&device, format, resolution, mask);
        Renderer {
            device,
            queue,
            geometry_pipeline,
            level_pipeline,
            board_pipeline,
            board_grid_depth_pipeline,
            board_depth: BoardDepth::default(),
            soft_board_pipelines,
            soft_edges: DEFAULT_SOFT_EDGES,
            octahedral_pipeline,
            quad,
            wire_pipeline,
            wireframe: false,
            board_layout,
            board_sampler,
            atlas_layout,
            draw_layout,
            draw_buffer,
            draw_bind_group,
            draw_capacity,
            board_grids,
            board_grid_at: Vec::new(),
            board_grid_index_offset: 0,
            target,
            spare: None,
            mask,
            adapter,
        }
    }

    /// The device (for a window's surface or an overlay).
    pub fn device(&self) -> &wgpu::Device {
        &self.device
    }

    /// The queue.
    pub fn queue(&self) -> &wgpu::Queue {
        &self.queue
    }

    /// Uploads an object's triangles, with crease-aware normals (the same the workers use, so
    /// geometry and boards are lit alike).
    pub fn upload_mesh(&self, object: &backend::PreparedObject) -> Mesh {
        let vertices: Vec<GeometryVertex> = object
            .vertices
            .iter()
            .map(|v| GeometryVertex {
                position: v.position.to_array(),
                normal: [snorm(v.normal.x), snorm(v.normal.y), snorm(v.normal.z), 0],
                color: v.color,
            })
            .collect();
        let vertex_buffer = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("mesh vertices"),
                contents: bytemuck::cast_slice(&vertices),
                usage: wgpu::BufferUsages::VERTEX,
            });
        let mut mesh = Mesh {
            vertices: vertex_buffer,
            levels: Vec::new(),
            origin: object.origin,
            triangles: object.triangles.len() as u64,
        };
        self.add_levels(&mut mesh, std::slice::from_ref(&object.triangles));
        mesh
    }

    /// Adds index lists into `mesh`'s vertices as its next levels of detail, finest first.
    pub fn add_levels(&self, mesh: &mut Mesh, levels: &[Vec<[u32; 3]>]) {
        mesh.levels.extend(levels.iter().map(|triangles| {
            let buffer = self
                .device
                .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("mesh indices"),
                    contents: bytemuck::cast_slice(triangles),
                    usage: wgpu::BufferUsages::INDEX,
                });
            (buffer, triangles.len() as u64)
        }));
    }

    /// Uploads `board` whole: [`Renderer::begin_board_upload`] and every band.
    pub fn upload_board(&self, board: &BoardData) -> GpuBoard {
        let mut upload = self.begin_board_upload(board);
        while !self.upload_board_band(&mut upload, board) {}
        upload.finish()
    }

    /// Starts uploading `board`: its texture (not yet written), grid and bind group. Its maps
    /// follow a band of rows at a time ([`Renderer::upload_board_band`]); it may be drawn once
    /// the last band is written ([`BoardUpload::finish`]).
    pub fn begin_board_upload(&self, board: &BoardData) -> BoardUpload {
        let side = board.size;
        let texture = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some("board maps"),
            size: wgpu::Extent3d {
                width: side,
                height: side,
                depth_or_array_layers: MAP_LAYERS,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba8Unorm,
            usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        let maps = texture.create_view(&wgpu::TextureViewDescriptor {
            dimension: Some(wgpu::TextureViewDimension::D2Array),
            ..Default::default()
        });
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("maps"),
            layout: &self.board_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(&maps),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Sampler(&self.board_sampler),
                },
            ],
        });
        let basis = &board.basis;
        let axes = glam::DMat3::from_cols(basis.right, basis.up, basis.forward) * basis.radius;
        BoardUpload {
            board: GpuBoard {
                bind_group,
                grid_vertices: board.vertices.clone(),
                grid_indices: board.indices.clone(),
                local_to_world: (basis.center, axes),
                flat: board.flat,
                bytes: board.gpu_bytes(),
            },
            texture,
            rows_written: 0,
        }
    }

    /// Writes the next band of `board`'s rows (every layer) into `upload`'s texture; true
    /// when that was the last.
    pub fn upload_board_band(&self, upload: &mut BoardUpload, board: &BoardData) -> bool {
        let side = board.size;
        let first = upload.rows_written;
        let rows = (UPLOAD_BAND_TEXELS / side).clamp(1, side - first);
        let row_bytes = side as usize * 4;
        for layer in 0..MAP_LAYERS {
            let start = (layer as usize * side as usize + first as usize) * row_bytes;
            self.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &upload.texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d {
                        x: 0,
                        y: first,
                        z: layer,
                    },
                    aspect: wgpu::TextureAspect::All,
                },
                &board.layers[start..start + rows as usize * row_bytes],
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(side * 4),
                    rows_per_image: Some(rows),
                },
                wgpu::Extent3d {
                    width: side,
                    height: rows,
                    depth_or_array_layers: 1,
                },
            );
        }
        upload.rows_written += rows;
        upload.rows_written == side
    }

    /// Uploads an object's octahedral atlas.
    pub fn upload_octahedral(&self, atlas: &crate::far_field::octahedral::Atlas) -> GpuOctahedral {
        GpuOctahedral {
            bind_group: self.atlas_bind_group(
                atlas.side(),
                &atlas.depth,
                &atlas.color,
                &atlas.normal,
            ),
            center: atlas.center,
            radius: atlas.radius,
            params: atlas.params,
            bytes: atlas.params.atlas_bytes(),
        }
    }

    /// The bind group of an octahedral atlas: `side x side` depth, colour and normal maps as
    /// three textures (see `atlas_layout`).
    fn atlas_bind_group(
        &self,
        side: u32,
        depth: &[f32],
        color: &[[u8; 4]],
        normal: &[[i8; 4]],
    ) -> wgpu::BindGroup {
        let texture = |label, format, bytes: &[u8]| {
            self.device
                .create_texture_with_data(
                    &self.queue,
                    &wgpu::TextureDescriptor {
                        label: Some(label),
                        size: wgpu::Extent3d {
                            width: side,
                            height: side,
                            depth_or_array_layers: 1,
                        },
                        mip_level_count: 1,
                        sample_count: 1,
                        dimension: wgpu::TextureDimension::D2,
                        format,
                        usage: wgpu::TextureUsages::TEXTURE_BINDING,
                        view_formats: &[],
                    },
                    wgpu::util::TextureDataOrder::LayerMajor,
                    bytes,
                )
                .create_view(&Default::default())
        };
        let views = [
            texture(
                "atlas depth",
                wgpu::TextureFormat::R32Float,
                bytemuck::cast_slice(depth),
            ),
            texture(
                "atlas colour",
                wgpu::TextureFormat::Rgba8Unorm,
                bytemuck::cast_slice(color),
            ),
            texture(
                "atlas normal",
                wgpu::TextureFormat::Rgba8Snorm,
                bytemuck::cast_slice(normal),
            ),
        ];
        let entries: Vec<wgpu::BindGroupEntry> = views
            .iter()
            .enumerate()
            .map(|(i, view)| wgpu::BindGroupEntry {
                binding: 2 + i as u32,
                resource: wgpu::BindingResource::TextureView(view),
            })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("octahedral atlas"),
            layout: &self.atlas_layout,
            entries: &entries,
        })
    }

    /// Resizes the offscreen target.
    pub fn resize(&mut self, resolution: [u32; 2]) {
        if resolution != self.target.size {
            let format = self.target.color.format();
            self.target = Target::new(&self.device, format, resolution, self.mask);
            self.spare = None;
        }
    }

    /// Swaps the offscreen target with a second one of the same size: the next frame draws
    /// into the other, and swapping again brings the earlier frame back for reading.
    pub fn swap_targets(&mut self) {
        let spare = match self.spare.take() {
            Some(spare) if spare.size == self.target.size => spare,
            _ => Target::new(
                &self.device,
                self.target.color.format(),
                self.target.size,
                self.mask,
            ),
        };
        self.spare = Some(std::mem::replace(&mut self.target, spare));
    }

    /// Draws `items` from `view` into the offscreen target and waits for the GPU.
    pub fn draw(&mut self, view: &View, items: &[DrawItem]) -> Result<FrameTiming, RenderError> {
        let start = Instant::now();
        let mut encoder = self.device.create_command_encoder(&Default::default());
        let color_view = self.target.color_view.clone();
        let mask_view = self.target.mask.as_ref().map(|(_, view)| view.clone());
        let depth_view = self.target.depth_view.clone();
        let triangles = self.record(
            &mut encoder,
            &color_view,
            mask_view.as_ref(),
            &depth_view,
            view,
            items,
        );
        self.queue.submit([encoder.finish()]);
        let cpu = start.elapsed();
        self.wait()?;
        Ok(FrameTiming {
            cpu_ms: ms(cpu),
            gpu_ms: ms(start.elapsed() - cpu),
            triangles,
        })
    }

    /// Records the frame's pass into `encoder`, targeting `color` and `depth`; returns the
    /// triangles submitted. For renderers made [`Renderer::with_device`] (no object mask).
    pub fn encode(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        depth: &wgpu::TextureView,
        view: &View,
        items: &[DrawItem],
    ) -> u64 {
        assert!(
            !self.mask,
            "an offscreen renderer's pipelines also write the object mask: use draw"
        );
        self.record(encoder, color, None, depth, view, items)
    }

    fn record(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        color: &wgpu::TextureView,
        mask: Option<&wgpu::TextureView>,
        depth: &wgpu::TextureView,
        view: &View,
        items: &[DrawItem],
    ) -> u64 {
        self.write_uniforms(view, items);
        self.write_board_grids(items);
        let mut triangles = 0;
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("frame"),
            color_attachments: &[
                Some(wgpu::RenderPassColorAttachment {
                    view: color,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color {
                            r: CLEAR_COLOR[0],
                            g: CLEAR_COLOR[1],
                            b: CLEAR_COLOR[2],
                            a: CLEAR_COLOR[3],
                        }),
                        store: wgpu::StoreOp::Store,
                    },
                }),
                mask.map(|view| wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                }),
            ],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: depth,
                depth_ops: Some(wgpu::Operations {
                    // Reverse-Z: the far plane is 0.
                    load: wgpu::LoadOp::Clear(0.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        // Bound once: every pipeline's group 0 is the draws, each draw picks its entry by its
        // instance index.
        pass.set_bind_group(0, &self.draw_bind_group, &[]);
        // Geometry first (it fills depth with early tests): full meshes, then coarser levels
        // (level 0 is the full mesh), then boards.
        for (pipeline, coarse) in [
            (&self.geometry_pipeline, false),
            (&self.level_pipeline, true),
        ] {
            pass.set_pipeline(pipeline);
            for (index, item) in items.iter().enumerate() {
                let DrawItem::Geometry { mesh, level, .. } = item else {
                    continue;
                };
                let level = (*level).min(mesh.levels.len() - 1);
                if (level > 0) != coarse {
                    continue;
                }
                let (indices, count) = &mesh.levels[level];
                pass.set_vertex_buffer(0, mesh.vertices.slice(..));
                pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..*count as u32 * 3, 0, instance(index));
                triangles += count;
            }
        }
        pass.set_pipeline(match (self.board_depth, self.soft_edges) {
            (BoardDepth::Pixel, false) => &self.board_pipeline,
            (BoardDepth::Grid, false) => &self.board_grid_depth_pipeline,
            (BoardDepth::Pixel, true) => &self.soft_board_pipelines.0,
            (BoardDepth::Grid, true) => &self.soft_board_pipelines.1,
        });
        self.bind_board_grids(&mut pass);
        for (index, item) in items.iter().enumerate() {
            if let DrawItem::Board { board, .. } = item {
                self.draw_board(&mut pass, index, board);
                triangles += board.triangles();
            }
        }
        pass.set_pipeline(&self.octahedral_pipeline);
        pass.set_vertex_buffer(0, self.quad.0.slice(..));
        pass.set_index_buffer(self.quad.1.slice(..), wgpu::IndexFormat::Uint32);
        for (index, item) in items.iter().enumerate() {
            if let DrawItem::Octahedral { impostor } = item {
                pass.set_bind_group(1, &impostor.bind_group, &[]);
                pass.draw_indexed(0..6, 0, instance(index));
                triangles += 2;
            }
        }
        if let Some(wire) = self.wire_pipeline.as_ref().filter(|_| self.wireframe) {
            pass.set_pipeline(wire);
            self.bind_board_grids(&mut pass);
            for (index, item) in items.iter().enumerate() {
                if let DrawItem::Board {
                    board,
                    outgoing: false,
                    ..
                } = item
                {
                    self.draw_board(&mut pass, index, board);
                }
            }
        }
        triangles
    }

    /// Draws the proxy grid of `board`, the `index`th item of the frame, with the bound
    /// pipeline and [`Renderer::bind_board_grids`].
    fn draw_board(&self, pass: &mut wgpu::RenderPass, index: usize, board: &GpuBoard) {
        let at = self.board_grid_at[index];
        pass.set_bind_group(1, &board.bind_group, &[]);
        pass.draw_indexed(
            at.first_index..at.first_index + board.grid_indices.len() as u32,
            at.base_vertex,
            instance(index),
        );
    }

    /// Copies the grids of the frame's boards into one buffer, so that uploading a board
    /// makes no buffer of its own (on lavapipe a buffer per board held the plant's uploads
    /// to two thirds of the boards a frame, README) and drawing it binds only its maps. A
    /// few hundred bytes a board, written each frame.
    fn write_board_grids(&mut self, items: &[DrawItem]) {
        self.board_grid_at.clear();
        self.board_grid_index_offset = 0;
        let (mut vertex_bytes, mut index_bytes) = (Vec::<u8>::new(), Vec::<u8>::new());
        let (mut vertices, mut indices) = (0u32, 0u32);
        for item in items {
            let DrawItem::Board { board, .. } = item else {
                self.board_grid_at.push(BoardGridAt::default());
                continue;
            };
            self.board_grid_at.push(BoardGridAt {
                first_index: indices,
                base_vertex: vertices as i32,
            });
            vertex_bytes.extend_from_slice(bytemuck::cast_slice(&board.grid_vertices));
            index_bytes.extend_from_slice(bytemuck::cast_slice(&board.grid_indices));
            vertices += board.grid_vertices.len() as u32;
            indices += board.grid_indices.len() as u32;
        }
        if indices == 0 {
            return;
        }
        let index_offset = vertex_bytes.len() as u64;
        let size = index_offset + index_bytes.len() as u64;
        if size > self.board_grids.size() {
            self.board_grids = board_grid_buffer(&self.device, size.next_power_of_two());
        }
        self.queue.write_buffer(&self.board_grids, 0, &vertex_bytes);
        self.queue
            .write_buffer(&self.board_grids, index_offset, &index_bytes);
        self.board_grid_index_offset = index_offset;
    }

    /// Binds the frame's board grids ([`Renderer::write_board_grids`]).
    fn bind_board_grids(&self, pass: &mut wgpu::RenderPass) {
        let split = self.board_grid_index_offset;
        if split == 0 {
            return;
        }
        pass.set_vertex_buffer(0, self.board_grids.slice(..split));
        pass.set_index_buffer(self.board_grids.slice(split..), wgpu::IndexFormat::Uint32);
    }

    /// Whether board wireframes can be drawn (the device draws lines from triangles).
    pub fn can_draw_wireframe(&self) -> bool {
        self.wire_pipeline.is_some()
    }

    /// The offscreen target's colour view (for drawing an overlay into a screenshot).
    pub fn offscreen_view(&self) -> &wgpu::TextureView {
        &self.target.color_view
    }

    fn write_uniforms(&mut self, view: &View, items: &[DrawItem]) {
        let needed = items.len().max(1) as u64;
        if needed > self.draw_capacity {
            self.draw_capacity = needed.next_power_of_two();
            (self.draw_buffer, self.draw_bind_group) =
                draw_buffer(&self.device, &self.draw_layout, self.draw_capacity);
        }
        let mut bytes = vec![0u8; (items.len() as u64 * DRAW_STRIDE) as usize];
        for (index, item) in items.iter().enumerate() {
            let uniform = match item {
                DrawItem::Geometry {
                    mesh, tint, object, ..
                } => DrawUniform {
                    clip_from_local: relative(
                        view,
                        DMat4::from_translation(mesh.origin - view.eye),
                    ),
                    params: [1.0, 0.0, 0.0, if *object { 1.0 } else { 0.0 }],
                    tint: *tint,
                    eye: [0.0; 4],
                },
                DrawItem::Board {
                    board,
                    fade,
                    outgoing,
                    tint,
                } => {
                    let (center, axes) = board.local_to_world;
                    let local = DMat4::from_mat3_translation(axes, center - view.eye);
                    // The eye in map coordinates, for the shader's per-pixel parallax.
                    let eye = (axes.inverse() * (view.eye - center)).as_vec3();
                    DrawUniform {
                        clip_from_local: relative(view, local),
                        params: [
                            *fade,
                            if *outgoing { 1.0 } else { 0.0 },
                            if board.flat { 1.0 } else { 0.0 },
                            1.0,
                        ],
                        tint: *tint,
                        // w: follow the pixel's ray (relief) or not (flat).
                        eye: [eye.x, eye.y, eye.z, if board.flat { 0.0 } else { 1.0 }],
                    }
                }
                DrawItem::Octahedral { impostor } => {
                    let eye = (view.eye - impostor.center).as_vec3();
                    DrawUniform {
                        clip_from_local: relative(
                            view,
                            DMat4::from_translation(impostor.center - view.eye),
                        ),
                        params: [
                            impostor.radius as f32,
                            impostor.params.views as f32,
                            impostor.params.view_size as f32,
                            1.0,
                        ],
                        tint: [0.0; 4],
                        eye: [eye.x, eye.y, eye.z, 0.0],
                    }
                }
            };
            let at = index * DRAW_STRIDE as usize;
            bytes[at..at + DRAW_STRIDE as usize].copy_from_slice(bytemuck::bytes_of(&uniform));
        }
        if !bytes.is_empty() {
            self.queue.write_buffer(&self.draw_buffer, 0, &bytes);
        }
    }

    /// Carries out the uploads made so far and frees their staging memory. Each mesh's
    /// data goes through a staging buffer that lives until a submission carries its copy
    /// and completes; on a device with one memory type (lavapipe, an integrated GPU) staging
    /// and meshes share the allocator's blocks, so a scene uploaded whole before its first
    /// frame left as much room again in them, unused. Call it between batches of uploads.
    pub fn finish_uploads(&self) -> Result<(), RenderError> {
        self.queue.submit([]);
        self.wait()
    }

    /// Waits until the GPU has finished all submitted work.
    pub fn wait(&self) -> Result<(), RenderError> {
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map(|_| ())
            .map_err(|e| RenderError::Device(e.to_string()))
    }

    /// Reads the offscreen target back as RGBA8 rows, top first.
    pub fn read_frame(&self) -> Result<Image, RenderError> {
        let [width, height] = self.target.size;
        let mut pixels = self.read_texture(&self.target.color, 4)?;
        // A window's surface format is often BGRA: the image is always RGBA.
        if matches!(
            self.target.color.format(),
            wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
        ) {
            for pixel in pixels.chunks_exact_mut(4) {
                pixel.swap(0, 2);
            }
        }
        Ok(Image {
            width,
            height,
            rgba: pixels,
        })
    }

    /// Reads the offscreen target's object mask back: per pixel, rows top first, whether a
    /// measured object (a suitable object's geometry, a board) was drawn there last.
    pub fn read_object_mask(&self) -> Result<Vec<bool>, RenderError> {
        let (texture, _) = self.target.mask.as_ref().ok_or_else(|| {
            RenderError::Device("this renderer draws into a window: it has no object mask".into())
        })?;
        Ok(self
            .read_texture(texture, 1)?
            .into_iter()
            .map(|v| v > 127)
            .collect())
    }

    /// Reads a frame-sized texture of `texel_bytes` per texel back, rows top first.
    fn read_texture(
        &self,
        texture: &wgpu::Texture,
        texel_bytes: u32,
    ) -> Result<Vec<u8>, RenderError> {
        let [width, height] = self.target.size;
        let row_bytes = (width * texel_bytes).div_ceil(256) * 256;
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("frame readback"),
            size: (row_bytes * height) as u64,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let mut encoder = self.device.create_command_encoder(&Default::default());
        encoder.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(row_bytes),
                    rows_per_image: Some(height),
                },
            },
            wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
        );
        self.queue.submit([encoder.finish()]);
        buffer.slice(..).map_async(wgpu::MapMode::Read, |_| {});
        self.wait()?;
        let mapped = buffer
            .slice(..)
            .get_mapped_range()
            .map_err(|e| RenderError::Device(e.to_string()))?;
        let row = (width * texel_bytes) as usize;
        let mut texels = Vec::with_capacity(row * height as usize);
        for at in (0..height as usize).map(|r| r * row_bytes as usize) {
            texels.extend_from_slice(&mapped[at..at + row]);
        }
        Ok(texels)
    }
}

/// An RGBA8 image, rows top first.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// RGBA bytes.
    pub rgba: Vec<u8>,
}

impl Target {
    fn new(
        device: &wgpu::Device,
        format: wgpu::TextureFormat,
        size: [u32; 2],
        mask: bool,
    ) -> Target {
        let readable = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        let color = frame_texture(device, format, readable, size);
        Target {
            mask: mask.then(|| {
                let texture = frame_texture(device, MASK_FORMAT, readable, size);
                let view = texture.create_view(&Default::default());
                (texture, view)
            }),
            color_view: color.create_view(&Default::default()),
            depth_view: depth_target(device, size),
            color,
            size,
        }
    }
}

/// A depth target for drawing into an external colour target (a window).
pub fn depth_target(device: &wgpu::Device, size: [u32; 2]) -> wgpu::TextureView {
    frame_texture(
        device,
        DEPTH_FORMAT,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
        size,
    )
    .create_view(&Default::default())
}

/// A frame-sized 2D texture (at least 1x1, so a minimised window still has one).
fn frame_texture(
    device: &wgpu::Device,
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
    size: [u32; 2],
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("frame"),
        size: wgpu::Extent3d {
            width: size[0].max(1),
            height: size[1].max(1),
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    })
}

/// The best adapter: a real GPU before a software one, and Vulkan, Metal or DirectX 12 before
/// OpenGL (on a machine without a GPU: lavapipe, not llvmpipe through GL), able to present to
/// `surface` when there is one. `WGPU_BACKEND` narrows the choice.
pub fn pick_adapter(
    instance: &wgpu::Instance,
    surface: Option<&wgpu::Surface>,
) -> Result<wgpu::Adapter, RenderError> {
    let adapter = best_adapter(instance, surface).ok_or_else(|| {
        RenderError::NoAdapter(if surface.is_some() {
            "wgpu found no adapter that can draw into this window".into()
        } else {
            "wgpu found no adapter".into()
        })
    })?;
    let info = adapter.get_info();
    if info.backend == wgpu::Backend::Gl {
        // llvmpipe over OpenGL draws several times fewer triangles a second than lavapipe:
        // every figure changes, so a user must know.
        eprintln!(
            "warning: drawing with {} over OpenGL: wgpu found no Vulkan adapter (or WGPU_BACKEND chose GL), and frame \
             times will differ from the README's (on a machine without a GPU install Mesa's \
             Vulkan driver: apt-get install mesa-vulkan-drivers libvulkan1)",
            info.name
        );
    }
    Ok(adapter)
}

/// [`pick_adapter`]'s choice, without a word.
fn best_adapter(
    instance: &wgpu::Instance,
    surface: Option<&wgpu::Surface>,
) -> Option<wgpu::Adapter> {
    let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
    let rank = |adapter: &wgpu::Adapter| {
        let info = adapter.get_info();
        let device = match info.device_type {
            wgpu::DeviceType::DiscreteGpu => 0,
            wgpu::DeviceType::IntegratedGpu => 1,
            wgpu::DeviceType::VirtualGpu => 2,
            wgpu::DeviceType::Other => 3,
            wgpu::DeviceType::Cpu => 4,
        };
        (device, (info.backend == wgpu::Backend::Gl) as u8)
    };
    adapters
        .into_iter()
        .filter(|adapter| surface.is_none_or(|s| adapter.is_surface_supported(s)))
        .min_by_key(rank)
}

/// The adapter [`Renderer::new`] would draw on (a window draws on the same one unless only
/// another can present to it), or `None` when wgpu finds none. Looked up once per process:
/// defaults chosen before a renderer exists (`t_nz`) depend on it.
pub fn headless_adapter() -> Option<&'static wgpu::AdapterInfo> {
    static INFO: std::sync::OnceLock<Option<wgpu::AdapterInfo>> = std::sync::OnceLock::new();
    INFO.get_or_init(|| {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        best_adapter(&instance, None).map(|adapter| adapter.get_info())
    })
    .as_ref()
}

/// Opens `adapter` with the largest textures and buffers it allows, and line drawing where it
/// has it (board wireframes); returns the device, its queue and a name for reports.
pub fn open_device(
    adapter: &wgpu::Adapter,
) -> Result<(wgpu::Device, wgpu::Queue, String), RenderError> {
    let limits = adapter.limits();
    let info = adapter.get_info();
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        required_features: adapter.features() & wgpu::Features::POLYGON_MODE_LINE,
        required_limits: wgpu::Limits {
            max_texture_dimension_2d: limits.max_texture_dimension_2d,
            max_buffer_size: limits.max_buffer_size,
            max_storage_buffer_binding_size: limits.max_storage_buffer_binding_size,
            ..wgpu::Limits::default()
        },
        ..Default::default()
    }))
    .map_err(|e| RenderError::Device(e.to_string()))?;
    Ok((device, queue, format!("{} ({:?})", info.name, info.backend)))
}

fn draw_buffer(
    device: &wgpu::Device,
    layout: &wgpu::BindGroupLayout,
    capacity: u64,
) -> (wgpu::Buffer, wgpu::BindGroup) {
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("draws"),
        size: capacity * DRAW_STRIDE,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("draws"),
        layout,
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: buffer.as_entire_binding(),
        }],
    });
    (buffer, bind_group)
}

/// The instances of the frame's `index`th draw: one, whose index picks the draw's entry.
fn instance(index: usize) -> std::ops::Range<u32> {
    index as u32..index as u32 + 1
}

/// Where a draw's board grid lies in the frame's grid buffer.
#[derive(Clone, Copy, Default)]
struct BoardGridAt {
    first_index: u32,
    base_vertex: i32,
}

/// A buffer for the frame's board grids of `size` bytes (at least one vertex's).
fn board_grid_buffer(device: &wgpu::Device, size: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("board grids"),
        size: size.max(16),
        usage: wgpu::BufferUsages::VERTEX
            | wgpu::BufferUsages::INDEX
            | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

fn relative(view: &View, local: DMat4) -> [f32; 16] {
    let m: Mat4 = (view.clip_from_relative * local).as_mat4();
    m.to_cols_array()
}

fn ms(duration: Duration) -> f64 {
    duration.as_secs_f64() * 1e3
}
