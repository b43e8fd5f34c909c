// Helpers shared by every volao shader stage.

// Index of voxel `id` in an x-fastest buffer of size `dims`.
fn linear_index(id: vec3<u32>, dims: vec3<u32>) -> u32 {
    return id.x + dims.x * (id.y + dims.y * id.z);
}

// True if `id` lies inside a grid of size `dims` (dispatches round up to whole workgroups).
fn in_grid(id: vec3<u32>, dims: vec3<u32>) -> bool {
    return all(id < dims);
}
