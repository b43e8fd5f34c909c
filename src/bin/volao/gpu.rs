//! `volao gpu`: the adapter volao will use, and a compute self-test on it.

use anyhow::{Result, bail};
use volao::volume::fmt_bytes;

/// `volao gpu`.
pub fn run() -> Result<()> {
    let start = std::time::Instant::now();
    let gpu = volao::gpu::request_device()?;
    println!("adapter:  {}", gpu.describe());
    println!("driver:   {} {}", gpu.info.driver, gpu.info.driver_info);
    let limits = gpu.device.limits();
    println!(
        "3-D textures up to {}³, storage buffers up to {}",
        limits.max_texture_dimension_3d,
        fmt_bytes(limits.max_storage_buffer_binding_size as u64)
    );
    println!("features: {:?}", gpu.device.features());
    let dims = [16, 16, 16];
    let out = volao::gpu::smoke::run(&gpu, dims)?;
    if out != volao::gpu::smoke::expected(dims) {
        bail!("GPU self-test: the compute shader's output differs from the CPU reference");
    }
    println!(
        "self-test: compute shader output matches the CPU reference ({:.0} ms)",
        start.elapsed().as_secs_f64() * 1e3
    );
    Ok(())
}
