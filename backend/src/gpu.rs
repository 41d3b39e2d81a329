//! A reference renderer on the GPU (wgpu): the same orthographic view of the same object into
//! depth, colour and normal targets, read back. It is what the software rasteriser is checked
//! against (stencil and depth must agree) and measured against (`backend bench`). On a
//! machine without a GPU it runs on Mesa's CPU Vulkan driver (lavapipe).

use glam::{DVec3, Mat4, Vec4};
use wgpu::util::DeviceExt;

use crate::object::PreparedObject;
use crate::raster::Basis;

/// Why the GPU reference cannot run.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum GpuError {
    /// No adapter (no GPU and no software Vulkan driver).
    #[error("no wgpu adapter available: {0}")]
    NoAdapter(String),
    /// The device could not be created or failed.
    #[error("wgpu device error: {0}")]
    Device(String),
    /// The request itself is invalid.
    #[error(transparent)]
    Render(#[from] crate::RenderError),
}

/// Maps read back from the GPU: depth in the software renderer's convention (`z` in
/// [-1, 1], -1 nearest, NaN uncovered), coverage, colour and normal.
#[derive(Debug, Clone)]
pub struct GpuMaps {
    /// Side in pixels.
    pub size: u32,
    /// View depth per pixel.
    pub depth: Vec<f32>,
    /// Coverage per pixel.
    pub stencil: Vec<bool>,
    /// Colour per pixel.
    pub color: Vec<[u8; 4]>,
}

/// A device with the pipeline ready.
pub struct GpuReference {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    /// The adapter's name and backend, for reports.
    pub adapter: String,
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GpuVertex {
    position: [f32; 3],
    normal: [f32; 3],
    color: [u8; 4],
}

const SHADER: &str = r#"
struct View { clip_from_local: mat4x4<f32> };
@group(0) @binding(0) var<uniform> view: View;

struct Varyings {
    @builtin(position) clip: vec4<f32>,
    @location(0) color: vec4<f32>,
    @location(1) normal: vec3<f32>,
};

@vertex
fn vs(@location(0) position: vec3<f32>, @location(1) normal: vec3<f32>, @location(2) color: vec4<f32>) -> Varyings {
    var out: Varyings;
    out.clip = view.clip_from_local * vec4<f32>(position, 1.0);
    out.color = color;
    out.normal = normal;
    return out;
}

struct Targets {
    @location(0) color: vec4<f32>,
    @location(1) normal: vec4<f32>,
};

@fragment
fn fs(in: Varyings) -> Targets {
    var out: Targets;
    out.color = in.color;
    out.normal = vec4<f32>(normalize(in.normal), 1.0);
    return out;
}
"#;

/// Set to `1` to let a test that needs a wgpu adapter skip, saying so, where none exists.
/// CI never sets it: there a missing adapter (Mesa's Vulkan driver not installed) fails.
pub const SKIP_GPU_TESTS_VARIABLE: &str = "RELIEFBOARD_SKIP_GPU_TESTS";

/// What a test does when it finds no wgpu adapter: fails with what to install, unless
/// [`SKIP_GPU_TESTS_VARIABLE`] is `1`, when it prints that it skips and returns (the caller
/// then returns too). A test that needs a GPU never passes silently without one.
pub fn no_adapter_in_test(test: &str, why: &dyn std::fmt::Display) {
    if std::env::var(SKIP_GPU_TESTS_VARIABLE).is_ok_and(|v| v == "1") {
        eprintln!("SKIPPED {test}: no wgpu adapter ({why}); {SKIP_GPU_TESTS_VARIABLE}=1 is set");
        return;
    }
    panic!(
        "{test} needs a wgpu adapter and found none: {why}. Install Mesa's Vulkan driver \
         (apt-get install mesa-vulkan-drivers libvulkan1; .ci/run does) or a GPU driver, or \
         set {SKIP_GPU_TESTS_VARIABLE}=1 to skip the tests that need one"
    );
}

impl GpuReference {
    /// Opens the first adapter wgpu finds (a GPU, or lavapipe).
    pub fn new() -> Result<GpuReference, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter =
            pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions::default()))
                .map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        let (device, queue) =
            pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor::default()))
                .map_err(|e| GpuError::Device(e.to_string()))?;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("reference"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("view"),
            entries: &[wgpu::BindGroupLayoutEntry {
                binding: 0,
                visibility: wgpu::ShaderStages::VERTEX,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Uniform,
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            }],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("reference"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let attributes = wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Unorm8x4];
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("reference"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<GpuVertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &attributes,
                })],
            },
            // Two-sided, like the software renderer.
            primitive: wgpu::PrimitiveState {
                cull_mode: None,
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: wgpu::TextureFormat::Depth32Float,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs"),
                compilation_options: Default::default(),
                targets: &[
                    Some(wgpu::TextureFormat::Rgba8Unorm.into()),
                    Some(wgpu::TextureFormat::Rgba16Float.into()),
                ],
            }),
            multiview_mask: None,
            cache: None,
        });
        Ok(GpuReference {
            device,
            queue,
            pipeline,
            layout,
            adapter: format!("{} ({:?})", info.name, info.backend),
        })
    }

    /// Uploads an object's vertices and triangles (done once per object, like a worker's
    /// stored replica).
    pub fn upload(&self, object: &PreparedObject) -> GpuObject {
        let vertices: Vec<GpuVertex> = object
            .vertices
            .iter()
            .map(|v| GpuVertex {
                position: (v.position - object.local_center).to_array(),
                normal: v.normal.to_array(),
                color: v.color,
            })
            .collect();
        let vertex_buffer = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("vertices"),
                contents: bytemuck::cast_slice(&vertices),
                usage: wgpu::BufferUsages::VERTEX,
            });
        let index_buffer = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("indices"),
                contents: bytemuck::cast_slice(&object.triangles),
                usage: wgpu::BufferUsages::INDEX,
            });
        GpuObject {
            vertex_buffer,
            index_buffer,
            indices: object.triangles.len() as u32 * 3,
            radius: object.radius,
            center: object.world_center(),
        }
    }

    /// Renders an uploaded object seen along `direction` and reads the maps back.
    pub fn render(
        &self,
        object: &GpuObject,
        direction: DVec3,
        size: u32,
    ) -> Result<GpuMaps, GpuError> {
        if size == 0 || size > crate::MAX_MAP_SIZE {
            return Err(crate::RenderError::BadResolution {
                size,
                max: crate::MAX_MAP_SIZE,
            }
            .into());
        }
        let basis = Basis::new(direction, object.center, object.radius)?;
        // Local (centred) position to clip space: x, y along right and up over the radius,
        // depth (z + 1) / 2 for wgpu's [0, 1] depth range.
        let scale = 1.0 / object.radius as f32;
        let (right, up, forward) = (
            basis.right.as_vec3() * scale,
            basis.up.as_vec3() * scale,
            basis.forward.as_vec3() * scale,
        );
        let clip_from_local = Mat4::from_cols(
            Vec4::new(right.x, up.x, forward.x * 0.5, 0.0),
            Vec4::new(right.y, up.y, forward.y * 0.5, 0.0),
            Vec4::new(right.z, up.z, forward.z * 0.5, 0.0),
            Vec4::new(0.0, 0.0, 0.5, 1.0),
        );
        let uniform = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("view"),
                contents: bytemuck::cast_slice(&clip_from_local.to_cols_array()),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let bind_group = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("view"),
            layout: &self.layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: uniform.as_entire_binding(),
            }],
        });
        let target = |format, usage| {
            self.device.create_texture(&wgpu::TextureDescriptor {
                label: None,
                size: wgpu::Extent3d {
                    width: size,
                    height: size,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let readable = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::COPY_SRC;
        let color = target(wgpu::TextureFormat::Rgba8Unorm, readable);
        let normal = target(
            wgpu::TextureFormat::Rgba16Float,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        let depth = target(wgpu::TextureFormat::Depth32Float, readable);
        let views = [&color, &normal, &depth].map(|t| t.create_view(&Default::default()));
        let row_bytes = (size * 4).div_ceil(256) * 256;
        let readback = |label| {
            self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: (row_bytes * size) as u64,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            })
        };
        let (color_buffer, depth_buffer) = (readback("color readback"), readback("depth readback"));
        let mut encoder = self.device.create_command_encoder(&Default::default());
        {
            let clear = wgpu::Operations {
                load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                store: wgpu::StoreOp::Store,
            };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("reference"),
                color_attachments: &[
                    Some(wgpu::RenderPassColorAttachment {
                        view: &views[0],
                        depth_slice: None,
                        resolve_target: None,
                        ops: clear,
                    }),
                    Some(wgpu::RenderPassColorAttachment {
                        view: &views[1],
                        depth_slice: None,
                        resolve_target: None,
                        ops: clear,
                    }),
                ],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &views[2],
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.set_vertex_buffer(0, object.vertex_buffer.slice(..));
            pass.set_index_buffer(object.index_buffer.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..object.indices, 0, 0..1);
        }
        for (texture, buffer, aspect) in [
            (&color, &color_buffer, wgpu::TextureAspect::All),
            (&depth, &depth_buffer, wgpu::TextureAspect::DepthOnly),
        ] {
            encoder.copy_texture_to_buffer(
                wgpu::TexelCopyTextureInfo {
                    texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect,
                },
                wgpu::TexelCopyBufferInfo {
                    buffer,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(row_bytes),
                        rows_per_image: Some(size),
                    },
                },
                wgpu::Extent3d {
                    width: size,
                    height: size,
                    depth_or_array_layers: 1,
                },
            );
        }
        self.queue.submit([encoder.finish()]);
        for buffer in [&color_buffer, &depth_buffer] {
            buffer.slice(..).map_async(wgpu::MapMode::Read, |_| {});
        }
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| GpuError::Device(e.to_string()))?;
        let pixels = (size * size) as usize;
        let mut maps = GpuMaps {
            size,
            depth: vec![f32::NAN; pixels],
            stencil: vec![false; pixels],
            color: vec![[0; 4]; pixels],
        };
        {
            let mapped = |buffer: &wgpu::Buffer| {
                buffer
                    .slice(..)
                    .get_mapped_range()
                    .map_err(|e| GpuError::Device(e.to_string()))
            };
            let (color_bytes, depth_bytes) = (mapped(&color_buffer)?, mapped(&depth_buffer)?);
            for row in 0..size as usize {
                for column in 0..size as usize {
                    let at = row * row_bytes as usize + column * 4;
                    let d = f32::from_le_bytes([
                        depth_bytes[at],
                        depth_bytes[at + 1],
                        depth_bytes[at + 2],
                        depth_bytes[at + 3],
                    ]);
                    let index = row * size as usize + column;
                    if d < 1.0 {
                        maps.depth[index] = d * 2.0 - 1.0;
                        maps.stencil[index] = true;
                        maps.color[index] = [
                            color_bytes[at],
                            color_bytes[at + 1],
                            color_bytes[at + 2],
                            color_bytes[at + 3],
                        ];
                    }
                }
            }
        }
        Ok(maps)
    }
}

/// An object uploaded to the GPU.
pub struct GpuObject {
    vertex_buffer: wgpu::Buffer,
    index_buffer: wgpu::Buffer,
    indices: u32,
    radius: f64,
    center: DVec3,
}
