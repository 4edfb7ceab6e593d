//! Rasterized first hits: a graphics pipeline that draws the scene's triangles
//! into a visibility buffer (triangle number + 1 per pixel, 0 where nothing
//! covers the pixel centre) with a reversed, infinite-far depth buffer, and
//! copies it into a storage buffer for compute passes. The projection is the
//! camera rays' pinhole model (`glsl/raster_visibility.vert`).

use std::sync::Arc;

use ash::vk;
use glam::Vec3;
use gpu_allocator::vulkan::{Allocation, AllocationCreateDesc, AllocationScheme};
use gpu_allocator::MemoryLocation;

use super::{shaders, Buffer, GpuContext};
use crate::consts::{RASTER_LOCATION_POSITION, RASTER_LOCATION_VISIBILITY, RASTER_VERTEX_BINDING};
use crate::error::{Error, Result, VkContext};

pub use crate::abi::RasterView;

impl RasterView {
    /// The view of the pinhole camera `[eye, forward, right, up]`
    /// ([`crate::scene::Camera::pinhole`]) whose rays pass through sub-pixel
    /// position `jitter` (0.5, 0.5 = the pixel centre) of a `width` × `height` image.
    pub fn new(pinhole: [Vec3; 4], jitter: [f32; 2], width: u32, height: u32, near: f32) -> RasterView {
        let [eye, forward, right, up] = pinhole;
        let v4 = |v: Vec3| [v.x, v.y, v.z, 0.0];
        RasterView {
            eye: v4(eye),
            right: v4(right / right.length_squared()),
            up: v4(up / up.length_squared()),
            forward: v4(forward),
            params: [near, 2.0 * (jitter[0] - 0.5) / width as f32, 2.0 * (jitter[1] - 0.5) / height as f32, 0.0],
        }
    }
}

struct Image {
    image: vk::Image,
    view: vk::ImageView,
    allocation: Option<Allocation>,
}

/// The visibility-buffer pipeline for one scene and image size. Dropping it
/// destroys its objects (no pending work may use them).
pub struct Rasterizer {
    ctx: Arc<GpuContext>,
    width: u32,
    height: u32,
    vertex_count: u32,
    vertices: Buffer,
    images: Vec<Image>,
    render_pass: vk::RenderPass,
    framebuffer: vk::Framebuffer,
    layout: vk::PipelineLayout,
    pipeline: vk::Pipeline,
}

const COLOR_FORMAT: vk::Format = vk::Format::R32_UINT;
const DEPTH_FORMAT: vk::Format = vk::Format::D32_SFLOAT;

impl Rasterizer {
    /// Uploads the triangles (3 vertices each) and creates the pipeline.
    ///
    /// Errors: `Error::DeviceLimit` when the context's queue cannot draw, the
    /// image exceeds the framebuffer limits, or the device cannot use a 32-bit
    /// float depth buffer; `Error::InvalidInput` for an empty image or scene.
    pub fn new(ctx: &Arc<GpuContext>, triangles: &[[Vec3; 3]], width: u32, height: u32) -> Result<Rasterizer> {
        if width == 0 || height == 0 || triangles.is_empty() {
            return Err(Error::InvalidInput("rasterizing needs at least one pixel and one triangle".into()));
        }
        let device = &ctx.device;
        // SAFETY: queries of the context's live physical device.
        let (families, limits, depth_props) = unsafe {
            (
                ctx.instance.get_physical_device_queue_family_properties(ctx.physical_device),
                ctx.instance.get_physical_device_properties(ctx.physical_device).limits,
                ctx.instance.get_physical_device_format_properties(ctx.physical_device, DEPTH_FORMAT),
            )
        };
        let graphics =
            families.get(ctx.queue_family as usize).is_some_and(|f| f.queue_flags.contains(vk::QueueFlags::GRAPHICS));
        if !graphics {
            return Err(Error::DeviceLimit(format!(
                "queue family {} of {} cannot draw: rasterized first hits need a graphics queue",
                ctx.queue_family, ctx.info.name
            )));
        }
        if width > limits.max_framebuffer_width || height > limits.max_framebuffer_height {
            return Err(Error::DeviceLimit(format!(
                "a {width}x{height} visibility buffer exceeds {}'s framebuffer limit of {}x{}",
                ctx.info.name, limits.max_framebuffer_width, limits.max_framebuffer_height
            )));
        }
        if !depth_props.optimal_tiling_features.contains(vk::FormatFeatureFlags::DEPTH_STENCIL_ATTACHMENT) {
            return Err(Error::DeviceLimit(format!("{} has no D32_SFLOAT depth attachments", ctx.info.name)));
        }
        let vertex_count = u32::try_from(triangles.len() * 3)
            .map_err(|_| Error::DeviceLimit(format!("{} triangles are too many to draw", triangles.len())))?;
        let positions: Vec<[f32; 3]> = triangles.iter().flat_map(|t| t.map(|v| v.to_array())).collect();
        let vertices = Buffer::with_data(
            ctx,
            bytemuck::cast_slice(&positions),
            vk::BufferUsageFlags::VERTEX_BUFFER,
            "raster vertices",
        )?;

        let mut r = Rasterizer {
            ctx: ctx.clone(),
            width,
            height,
            vertex_count,
            vertices,
            images: Vec::new(),
            render_pass: vk::RenderPass::null(),
            framebuffer: vk::Framebuffer::null(),
            layout: vk::PipelineLayout::null(),
            pipeline: vk::Pipeline::null(),
        };
        let color_usage = vk::ImageUsageFlags::COLOR_ATTACHMENT | vk::ImageUsageFlags::TRANSFER_SRC;
        r.add_image(COLOR_FORMAT, color_usage, vk::ImageAspectFlags::COLOR, "visibility")?;
        r.add_image(DEPTH_FORMAT, vk::ImageUsageFlags::DEPTH_STENCIL_ATTACHMENT, vk::ImageAspectFlags::DEPTH, "depth")?;

        let attachments = [
            vk::AttachmentDescription::default()
                .format(COLOR_FORMAT)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::STORE)
                .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
                .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(vk::ImageLayout::UNDEFINED)
                .final_layout(vk::ImageLayout::TRANSFER_SRC_OPTIMAL),
            vk::AttachmentDescription::default()
                .format(DEPTH_FORMAT)
                .samples(vk::SampleCountFlags::TYPE_1)
                .load_op(vk::AttachmentLoadOp::CLEAR)
                .store_op(vk::AttachmentStoreOp::DONT_CARE)
                .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
                .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
                .initial_layout(vk::ImageLayout::UNDEFINED)
                .final_layout(vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL),
        ];
        // The subpass's color attachment `RASTER_LOCATION_VISIBILITY` (the only one) is attachment 0.
        let color_ref = [vk::AttachmentReference { attachment: 0, layout: vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL }];
        const { assert!(RASTER_LOCATION_VISIBILITY == 0) };
        let depth_ref =
            vk::AttachmentReference { attachment: 1, layout: vk::ImageLayout::DEPTH_STENCIL_ATTACHMENT_OPTIMAL };
        let subpass = [vk::SubpassDescription::default()
            .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
            .color_attachments(&color_ref)
            .depth_stencil_attachment(&depth_ref)];
        let attachment_stages =
            vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT | vk::PipelineStageFlags::EARLY_FRAGMENT_TESTS;
        let dependencies = [
            // The previous frame's copy of the visibility image before this frame clears it.
            vk::SubpassDependency::default()
                .src_subpass(vk::SUBPASS_EXTERNAL)
                .dst_subpass(0)
                .src_stage_mask(vk::PipelineStageFlags::TRANSFER | attachment_stages)
                .dst_stage_mask(attachment_stages)
                .src_access_mask(vk::AccessFlags::TRANSFER_READ | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_WRITE)
                .dst_access_mask(
                    vk::AccessFlags::COLOR_ATTACHMENT_WRITE | vk::AccessFlags::DEPTH_STENCIL_ATTACHMENT_WRITE,
                ),
            // The drawn visibility before its copy.
            vk::SubpassDependency::default()
                .src_subpass(0)
                .dst_subpass(vk::SUBPASS_EXTERNAL)
                .src_stage_mask(vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT)
                .dst_stage_mask(vk::PipelineStageFlags::TRANSFER)
                .src_access_mask(vk::AccessFlags::COLOR_ATTACHMENT_WRITE)
                .dst_access_mask(vk::AccessFlags::TRANSFER_READ),
        ];
        let pass_info = vk::RenderPassCreateInfo::default()
            .attachments(&attachments)
            .subpasses(&subpass)
            .dependencies(&dependencies);
        // SAFETY: valid create infos on a live device; `r`'s Drop destroys what is made.
        unsafe {
            r.render_pass = device.create_render_pass(&pass_info, None).vk("vkCreateRenderPass")?;
            let views = [r.images[0].view, r.images[1].view];
            let fb_info = vk::FramebufferCreateInfo::default()
                .render_pass(r.render_pass)
                .attachments(&views)
                .width(width)
                .height(height)
                .layers(1);
            r.framebuffer = device.create_framebuffer(&fb_info, None).vk("vkCreateFramebuffer")?;
            let push = [vk::PushConstantRange::default()
                .stage_flags(vk::ShaderStageFlags::VERTEX)
                .offset(0)
                .size(std::mem::size_of::<RasterView>() as u32)];
            r.layout = device
                .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().push_constant_ranges(&push), None)
                .vk("vkCreatePipelineLayout")?;
            r.pipeline = r.create_pipeline()?;
        }
        Ok(r)
    }

    fn add_image(
        &mut self,
        format: vk::Format,
        usage: vk::ImageUsageFlags,
        aspect: vk::ImageAspectFlags,
        name: &str,
    ) -> Result<()> {
        let device = &self.ctx.device;
        let info = vk::ImageCreateInfo::default()
            .image_type(vk::ImageType::TYPE_2D)
            .format(format)
            .extent(vk::Extent3D { width: self.width, height: self.height, depth: 1 })
            .mip_levels(1)
            .array_layers(1)
            .samples(vk::SampleCountFlags::TYPE_1)
            .tiling(vk::ImageTiling::OPTIMAL)
            .usage(usage)
            .sharing_mode(vk::SharingMode::EXCLUSIVE)
            .initial_layout(vk::ImageLayout::UNDEFINED);
        // SAFETY: a valid create info; the image joins `self.images` at once, so
        // Drop destroys it (and its view and memory once made) on any error below.
        unsafe {
            let image = device.create_image(&info, None).vk("vkCreateImage")?;
            self.images.push(Image { image, view: vk::ImageView::null(), allocation: None });
            let requirements = device.get_image_memory_requirements(image);
            let allocation =
                self.ctx.allocator().lock().unwrap_or_else(|p| p.into_inner()).allocate(&AllocationCreateDesc {
                    name,
                    requirements,
                    location: MemoryLocation::GpuOnly,
                    linear: false,
                    allocation_scheme: AllocationScheme::GpuAllocatorManaged,
                })?;
            let (memory, offset) = (allocation.memory(), allocation.offset());
            self.images.last_mut().unwrap().allocation = Some(allocation);
            device.bind_image_memory(image, memory, offset).vk("vkBindImageMemory")?;
            let view_info = vk::ImageViewCreateInfo::default()
                .image(image)
                .view_type(vk::ImageViewType::TYPE_2D)
                .format(format)
                .subresource_range(vk::ImageSubresourceRange {
                    aspect_mask: aspect,
                    base_mip_level: 0,
                    level_count: 1,
                    base_array_layer: 0,
                    layer_count: 1,
                });
            self.images.last_mut().unwrap().view =
                device.create_image_view(&view_info, None).vk("vkCreateImageView")?;
        }
        Ok(())
    }

    /// # Safety
    /// `self.layout` and `self.render_pass` are live.
    unsafe fn create_pipeline(&self) -> Result<vk::Pipeline> {
        let device = &self.ctx.device;
        let module = |spirv: &[u8], what: &str| -> Result<vk::ShaderModule> {
            let code = ash::util::read_spv(&mut std::io::Cursor::new(spirv))
                .map_err(|e| Error::InvalidInput(format!("{what}: bad SPIR-V: {e}")))?;
            device
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(&code), None)
                .vk("vkCreateShaderModule")
        };
        let vert = module(shaders::RASTER_VISIBILITY_VERT, "raster_visibility.vert")?;
        let frag = match module(shaders::RASTER_VISIBILITY_FRAG, "raster_visibility.frag") {
            Ok(f) => f,
            Err(e) => {
                device.destroy_shader_module(vert, None);
                return Err(e);
            }
        };
        let stages = [
            vk::PipelineShaderStageCreateInfo::default().stage(vk::ShaderStageFlags::VERTEX).module(vert).name(c"main"),
            vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::FRAGMENT)
                .module(frag)
                .name(c"main"),
        ];
        let bindings = [vk::VertexInputBindingDescription {
            binding: RASTER_VERTEX_BINDING,
            stride: std::mem::size_of::<[f32; 3]>() as u32,
            input_rate: vk::VertexInputRate::VERTEX,
        }];
        let attributes = [vk::VertexInputAttributeDescription {
            location: RASTER_LOCATION_POSITION,
            binding: RASTER_VERTEX_BINDING,
            format: vk::Format::R32G32B32_SFLOAT,
            offset: 0,
        }];
        let vertex_input = vk::PipelineVertexInputStateCreateInfo::default()
            .vertex_binding_descriptions(&bindings)
            .vertex_attribute_descriptions(&attributes);
        let assembly =
            vk::PipelineInputAssemblyStateCreateInfo::default().topology(vk::PrimitiveTopology::TRIANGLE_LIST);
        let viewports = [vk::Viewport {
            x: 0.0,
            y: 0.0,
            width: self.width as f32,
            height: self.height as f32,
            min_depth: 0.0,
            max_depth: 1.0,
        }];
        let scissors = [vk::Rect2D { offset: vk::Offset2D { x: 0, y: 0 }, extent: self.extent() }];
        let viewport = vk::PipelineViewportStateCreateInfo::default().viewports(&viewports).scissors(&scissors);
        let raster = vk::PipelineRasterizationStateCreateInfo::default()
            .polygon_mode(vk::PolygonMode::FILL)
            .cull_mode(vk::CullModeFlags::NONE)
            .front_face(vk::FrontFace::COUNTER_CLOCKWISE)
            .line_width(1.0);
        let multisample =
            vk::PipelineMultisampleStateCreateInfo::default().rasterization_samples(vk::SampleCountFlags::TYPE_1);
        let depth = vk::PipelineDepthStencilStateCreateInfo::default()
            .depth_test_enable(true)
            .depth_write_enable(true)
            .depth_compare_op(vk::CompareOp::GREATER);
        let blend_attachments =
            [vk::PipelineColorBlendAttachmentState::default().color_write_mask(vk::ColorComponentFlags::R)];
        let blend = vk::PipelineColorBlendStateCreateInfo::default().attachments(&blend_attachments);
        let info = [vk::GraphicsPipelineCreateInfo::default()
            .stages(&stages)
            .vertex_input_state(&vertex_input)
            .input_assembly_state(&assembly)
            .viewport_state(&viewport)
            .rasterization_state(&raster)
            .multisample_state(&multisample)
            .depth_stencil_state(&depth)
            .color_blend_state(&blend)
            .layout(self.layout)
            .render_pass(self.render_pass)
            .subpass(0)];
        let pipelines = device.create_graphics_pipelines(self.ctx.pipeline_cache(), &info, None);
        device.destroy_shader_module(vert, None);
        device.destroy_shader_module(frag, None);
        match pipelines {
            Ok(p) => Ok(p[0]),
            Err((_, result)) => Err(Error::Vulkan { what: "vkCreateGraphicsPipelines", result }),
        }
    }

    fn extent(&self) -> vk::Extent2D {
        vk::Extent2D { width: self.width, height: self.height }
    }

    /// Bytes of the visibility buffer [`Rasterizer::record`] fills (a `uint` per pixel).
    pub fn visibility_bytes(&self) -> u64 {
        u64::from(self.width) * u64::from(self.height) * std::mem::size_of::<u32>() as u64
    }

    /// Records the draw of the visibility buffer seen through `view`, then its
    /// copy into `visibility` (row-major, one u32 per pixel, at offset 0). After
    /// it, a barrier from `TRANSFER` writes to the reader is the caller's.
    ///
    /// # Safety
    /// `cmd` must be recording outside a render pass on the context's queue
    /// family; `visibility` must be a buffer of at least
    /// [`Rasterizer::visibility_bytes`] with `TRANSFER_DST` usage; both and this
    /// rasterizer must live until `cmd` completes.
    pub unsafe fn record(&self, cmd: vk::CommandBuffer, view: &RasterView, visibility: &Buffer) {
        self.ctx.note_draw();
        let device = &self.ctx.device;
        let clear = [
            vk::ClearValue { color: vk::ClearColorValue { uint32: [0; 4] } },
            vk::ClearValue { depth_stencil: vk::ClearDepthStencilValue { depth: 0.0, stencil: 0 } },
        ];
        let begin = vk::RenderPassBeginInfo::default()
            .render_pass(self.render_pass)
            .framebuffer(self.framebuffer)
            .render_area(vk::Rect2D { offset: vk::Offset2D { x: 0, y: 0 }, extent: self.extent() })
            .clear_values(&clear);
        device.cmd_begin_render_pass(cmd, &begin, vk::SubpassContents::INLINE);
        device.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::GRAPHICS, self.pipeline);
        device.cmd_push_constants(cmd, self.layout, vk::ShaderStageFlags::VERTEX, 0, bytemuck::bytes_of(view));
        device.cmd_bind_vertex_buffers(cmd, RASTER_VERTEX_BINDING, &[self.vertices.buffer], &[0]);
        device.cmd_draw(cmd, self.vertex_count, 1, 0, 0);
        device.cmd_end_render_pass(cmd);
        let region = vk::BufferImageCopy {
            buffer_offset: 0,
            buffer_row_length: 0,
            buffer_image_height: 0,
            image_subresource: vk::ImageSubresourceLayers {
                aspect_mask: vk::ImageAspectFlags::COLOR,
                mip_level: 0,
                base_array_layer: 0,
                layer_count: 1,
            },
            image_offset: vk::Offset3D { x: 0, y: 0, z: 0 },
            image_extent: vk::Extent3D { width: self.width, height: self.height, depth: 1 },
        };
        device.cmd_copy_image_to_buffer(
            cmd,
            self.images[0].image,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            visibility.buffer,
            &[region],
        );
    }
}

impl Drop for Rasterizer {
    fn drop(&mut self) {
        let device = &self.ctx.device;
        // SAFETY: no pending work uses these objects (the type's contract); null
        // handles are ignored by the destroy calls.
        unsafe {
            device.destroy_pipeline(self.pipeline, None);
            device.destroy_pipeline_layout(self.layout, None);
            device.destroy_framebuffer(self.framebuffer, None);
            device.destroy_render_pass(self.render_pass, None);
            for image in self.images.drain(..) {
                device.destroy_image_view(image.view, None);
                device.destroy_image(image.image, None);
                if let Some(a) = image.allocation {
                    let _ = self.ctx.allocator().lock().unwrap_or_else(|p| p.into_inner()).free(a);
                }
            }
        }
    }
}
