//! Bottom- and top-level acceleration structures for ray query: one BLAS per mesh and one TLAS
//! instance per mesh, so the instance id a ray query reports is the mesh index and the primitive
//! id is the triangle index within that mesh — the same ids the CPU backend reports.

use super::buffer::{submit_and_wait, GpuBuffer};
use super::context::{vk_error, AccelerationLimits, Core};
use super::driver_lock;
use crate::error::{Error, Result};
use crate::scene::Scene;
use ash::vk;
use gpu_allocator::MemoryLocation;
use std::sync::Arc;

/// An acceleration structure with the buffer that stores it; destroyed on drop.
pub(crate) struct AccelerationStructure {
    core: Arc<Core>,
    pub handle: vk::AccelerationStructureKHR,
    pub address: u64,
    _storage: GpuBuffer,
}

impl Drop for AccelerationStructure {
    fn drop(&mut self) {
        if self.core.is_wedged() {
            // Leaked: a submission may still use it (`Core::wedge`).
            return;
        }
        let _driver = driver_lock::device_use();
        if let Some(accel) = &self.core.acceleration_structure {
            // SAFETY: the device is idle after every submission, so no command uses it.
            unsafe { accel.destroy_acceleration_structure(self.handle, None) };
        }
    }
}

/// A scene's acceleration structures, ready to bind.
pub(crate) struct SceneAccel {
    pub tlas: AccelerationStructure,
    _blases: Vec<AccelerationStructure>,
}

const INPUT_USAGE: vk::BufferUsageFlags = vk::BufferUsageFlags::from_raw(
    vk::BufferUsageFlags::ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_KHR.as_raw()
        | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS.as_raw(),
);

/// One pending build: its geometry description, primitive count and level (bottom or top).
struct Build<'a> {
    geometry: [vk::AccelerationStructureGeometryKHR<'a>; 1],
    primitive_count: u32,
    level: vk::AccelerationStructureTypeKHR,
}

fn build_info<'a>(build: &'a Build<'a>) -> vk::AccelerationStructureBuildGeometryInfoKHR<'a> {
    vk::AccelerationStructureBuildGeometryInfoKHR::default()
        .ty(build.level)
        .flags(vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE)
        .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
        .geometries(&build.geometry)
}

/// Allocates and builds the acceleration structures of `builds` (all of one level, at least
/// one: a scene has a mesh with a triangle, `Scene::validate`) in one submission.
fn build_all(core: &Arc<Core>, builds: &[Build<'_>]) -> Result<Vec<AccelerationStructure>> {
    let accel = core.acceleration_structure.as_ref().ok_or_else(|| Error::MissingFeatures {
        device: core.info.name.clone(),
        stage: "trace".into(),
        missing: vec!["VK_KHR_acceleration_structure".into()],
    })?;
    let mut structures = Vec::with_capacity(builds.len());
    let mut scratch_offsets = Vec::with_capacity(builds.len());
    let mut scratch_total = 0u64;
    for build in builds {
        let info = build_info(build);
        let mut sizes = vk::AccelerationStructureBuildSizesInfoKHR::default();
        // SAFETY: `info` describes valid geometry; only sizes are queried.
        unsafe {
            accel.get_acceleration_structure_build_sizes(
                vk::AccelerationStructureBuildTypeKHR::DEVICE,
                &info,
                &[build.primitive_count],
                &mut sizes,
            )
        };
        let storage = GpuBuffer::new(
            core,
            sizes.acceleration_structure_size,
            vk::BufferUsageFlags::ACCELERATION_STRUCTURE_STORAGE_KHR | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            MemoryLocation::GpuOnly,
            "acceleration structure",
        )?;
        let create = vk::AccelerationStructureCreateInfoKHR::default()
            .buffer(storage.buffer)
            .size(sizes.acceleration_structure_size)
            .ty(build.level);
        // SAFETY: `storage` is large enough and outlives the structure (owned by it).
        let handle = unsafe { accel.create_acceleration_structure(&create, None) }
            .map_err(vk_error("vkCreateAccelerationStructureKHR"))?;
        // SAFETY: `handle` is a live acceleration structure.
        let address = unsafe {
            accel.get_acceleration_structure_device_address(
                &vk::AccelerationStructureDeviceAddressInfoKHR::default().acceleration_structure(handle),
            )
        };
        structures.push(AccelerationStructure { core: core.clone(), handle, address, _storage: storage });
        scratch_offsets.push(scratch_total);
        scratch_total += sizes.build_scratch_size.next_multiple_of(core.accel_limits.scratch_alignment);
    }
    let scratch = GpuBuffer::new(
        core,
        scratch_total + core.accel_limits.scratch_alignment,
        vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
        MemoryLocation::GpuOnly,
        "acceleration structure scratch",
    )?;
    let scratch_base = scratch.address.next_multiple_of(core.accel_limits.scratch_alignment);
    let infos: Vec<_> = builds
        .iter()
        .zip(&structures)
        .zip(&scratch_offsets)
        .map(|((build, structure), offset)| {
            build_info(build)
                .dst_acceleration_structure(structure.handle)
                .scratch_data(vk::DeviceOrHostAddressKHR { device_address: scratch_base + offset })
        })
        .collect();
    let ranges: Vec<[vk::AccelerationStructureBuildRangeInfoKHR; 1]> = builds
        .iter()
        .map(|b| [vk::AccelerationStructureBuildRangeInfoKHR::default().primitive_count(b.primitive_count)])
        .collect();
    let range_refs: Vec<&[vk::AccelerationStructureBuildRangeInfoKHR]> = ranges.iter().map(|r| r.as_slice()).collect();
    submit_and_wait(core, |cmd| {
        // SAFETY: all referenced buffers and structures are alive until the wait completes.
        unsafe { accel.cmd_build_acceleration_structures(cmd, &infos, &range_refs) };
    })?;
    drop(scratch);
    Ok(structures)
}

/// Checks `scene` against device `device`'s acceleration-structure limits: at most
/// `maxInstanceCount` meshes (one instance each) and `maxPrimitiveCount` triangles a mesh.
/// Building past them is invalid usage — a lost device at best — so it is an error before
/// anything is uploaded.
pub(crate) fn check_limits(scene: &Scene, limits: &AccelerationLimits, device: &str) -> Result<()> {
    let meshes = scene.meshes();
    let too_large = |what: String| Err(Error::SceneTooLarge { scene: scene.name().to_owned(), what });
    if meshes.len() as u64 > limits.max_instances {
        return too_large(format!(
            "{} meshes, more than {device}'s maxInstanceCount {}",
            meshes.len(),
            limits.max_instances
        ));
    }
    match meshes.iter().find(|m| m.triangles.len() as u64 > limits.max_triangles) {
        Some(mesh) => too_large(format!(
            "mesh {:?} has {} triangles, more than {device}'s maxPrimitiveCount {}",
            mesh.name,
            mesh.triangles.len(),
            limits.max_triangles
        )),
        None => Ok(()),
    }
}

/// Builds one BLAS per mesh and a TLAS over them (identity transforms, instance i = mesh i)
/// for a scene that [`check_limits`] accepted (the caller checks it first, so that a refused
/// scene leaves the loaded one in place).
pub(crate) fn build_scene(core: &Arc<Core>, scene: &Scene) -> Result<SceneAccel> {
    let meshes = scene.meshes();
    // Every mesh's vertices in one buffer and its indices in another — two uploads, each a
    // blocking submission, rather than two per mesh — and each BLAS reads its own range. The
    // ranges start at multiples of 12 bytes, aligned for the f32 vertices and u32 indices.
    let vertices: Vec<[f32; 3]> = meshes.iter().flat_map(|m| m.positions.iter().map(|p| p.to_array())).collect();
    let indices: Vec<u32> = meshes.iter().flat_map(|m| m.triangles.iter().flatten().copied()).collect();
    let vertex_buffer = GpuBuffer::with_data(core, &vertices, INPUT_USAGE, "blas vertices")?;
    let index_buffer = GpuBuffer::with_data(core, &indices, INPUT_USAGE, "blas indices")?;
    let mut start = (vertex_buffer.address, index_buffer.address);
    let blas_builds: Vec<Build> = meshes
        .iter()
        .map(|mesh| {
            let (vertex_address, index_address) = start;
            start.0 += 12 * mesh.positions.len() as u64;
            start.1 += 12 * mesh.triangles.len() as u64;
            let triangles = vk::AccelerationStructureGeometryTrianglesDataKHR::default()
                .vertex_format(vk::Format::R32G32B32_SFLOAT)
                .vertex_data(vk::DeviceOrHostAddressConstKHR { device_address: vertex_address })
                .vertex_stride(12)
                .max_vertex((mesh.positions.len() as u32).saturating_sub(1))
                .index_type(vk::IndexType::UINT32)
                .index_data(vk::DeviceOrHostAddressConstKHR { device_address: index_address });
            Build {
                geometry: [vk::AccelerationStructureGeometryKHR::default()
                    .geometry_type(vk::GeometryTypeKHR::TRIANGLES)
                    .geometry(vk::AccelerationStructureGeometryDataKHR { triangles })
                    .flags(vk::GeometryFlagsKHR::OPAQUE)],
                primitive_count: mesh.triangles.len() as u32,
                level: vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            }
        })
        .collect();
    let blases = build_all(core, &blas_builds)?;
    // The builds have completed (`build_all` waits): their inputs can go.
    drop((vertex_buffer, index_buffer));

    let identity = vk::TransformMatrixKHR { matrix: [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0] };
    let instances: Vec<vk::AccelerationStructureInstanceKHR> = blases
        .iter()
        .map(|blas| vk::AccelerationStructureInstanceKHR {
            transform: identity,
            // No shader reads the custom index (they read the instance index, which is the mesh
            // index), so 0 rather than a mesh index that 24 bits would wrap.
            instance_custom_index_and_mask: vk::Packed24_8::new(0, 0xff),
            instance_shader_binding_table_record_offset_and_flags: vk::Packed24_8::new(
                0,
                vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE.as_raw() as u8,
            ),
            acceleration_structure_reference: vk::AccelerationStructureReferenceKHR { device_handle: blas.address },
        })
        .collect();
    // SAFETY: `AccelerationStructureInstanceKHR` is a plain #[repr(C)] struct of 64 bytes with no
    // padding; viewing it as bytes is sound.
    let instance_bytes = unsafe {
        std::slice::from_raw_parts(instances.as_ptr().cast::<u8>(), std::mem::size_of_val(instances.as_slice()))
    };
    let instance_buffer = GpuBuffer::with_data(core, instance_bytes, INPUT_USAGE, "tlas instances")?;
    let tlas_build = Build {
        geometry: [vk::AccelerationStructureGeometryKHR::default()
            .geometry_type(vk::GeometryTypeKHR::INSTANCES)
            .geometry(vk::AccelerationStructureGeometryDataKHR {
                instances: vk::AccelerationStructureGeometryInstancesDataKHR::default()
                    .array_of_pointers(false)
                    .data(vk::DeviceOrHostAddressConstKHR { device_address: instance_buffer.address }),
            })
            .flags(vk::GeometryFlagsKHR::OPAQUE)],
        primitive_count: instances.len() as u32,
        level: vk::AccelerationStructureTypeKHR::TOP_LEVEL,
    };
    let tlas = build_all(core, std::slice::from_ref(&tlas_build))?.remove(0);
    drop(instance_buffer);
    Ok(SceneAccel { tlas, _blases: blases })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_scene_past_the_devices_limits_is_refused_before_any_build() {
        let scene = Scene::load("builtin:cornell").unwrap();
        let meshes = scene.meshes().len() as u64;
        let most = scene.meshes().iter().map(|m| m.triangles.len() as u64).max().unwrap();
        let fits = AccelerationLimits { scratch_alignment: 1, max_instances: meshes, max_triangles: most };
        assert!(check_limits(&scene, &fits, "a GPU").is_ok());
        for (limits, expected) in [
            (AccelerationLimits { max_instances: meshes - 1, ..fits }, "maxInstanceCount"),
            (AccelerationLimits { max_triangles: most - 1, ..fits }, "maxPrimitiveCount"),
        ] {
            let err = check_limits(&scene, &limits, "a GPU").unwrap_err();
            assert!(matches!(err, Error::SceneTooLarge { .. }) && err.to_string().contains(expected), "{err}");
        }
    }
}
