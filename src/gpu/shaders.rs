//! WGSL sources, embedded in the binary, with a tiny `//!include name.wgsl` resolver.
//!
//! WGSL has no includes. A line `//!include common.wgsl` (a comment, so every file
//! still parses on its own) is replaced by that file's text, once per shader.
//!
//! Shader variants use two mechanisms, never edits of the text: `override` constants
//! set per pipeline ([`Constants`]: what a variant compiles out), and includes swapped
//! for other files ([`module_swapping`]: what WGSL cannot override, a storage format).

use super::GpuError;

/// Every shader in `shaders/`, embedded at build time. A test checks this list against
/// the directory so a new file cannot be forgotten.
/// `(name, source)` of `shaders/name`, embedded at compile time.
macro_rules! shader {
    ($name:literal) => {
        ($name, include_str!(concat!("../../shaders/", $name)))
    };
}

pub const SOURCES: &[(&str, &str)] = &[
    shader!("ambient_maps.wgsl"),
    shader!("box_stats.wgsl"),
    shader!("bricks.wgsl"),
    shader!("cao_clip.wgsl"),
    shader!("cao_format.wgsl"),
    shader!("cao_format_r32.wgsl"),
    shader!("cao_gather.wgsl"),
    shader!("cao_lao.wgsl"),
    shader!("cao_listed.wgsl"),
    shader!("cao_params.wgsl"),
    shader!("cao_ray.wgsl"),
    shader!("clip_common.wgsl"),
    shader!("clip_depth.wgsl"),
    shader!("clip_maps.wgsl"),
    shader!("common.wgsl"),
    shader!("cone.wgsl"),
    shader!("gradient.wgsl"),
    shader!("lao.wgsl"),
    shader!("lao_ray.wgsl"),
    shader!("light.wgsl"),
    shader!("raycast.wgsl"),
    shader!("readable.wgsl"),
    shader!("smoke.wgsl"),
    shader!("viewport.wgsl"),
    shader!("surface.wgsl"),
    shader!("vao.wgsl"),
    shader!("vao_common.wgsl"),
    shader!("volume.wgsl"),
];

const DIRECTIVE: &str = "//!include ";

/// Values of a pipeline's `override` constants, by name: one variant of a shader.
pub type Constants = &'static [(&'static str, f64)];

/// Includes to resolve to other files, `(included, instead)`.
pub type Swaps<'a> = &'a [(&'a str, &'a str)];

/// The embedded source of `name` with its includes resolved.
pub fn source(name: &str) -> Result<String, GpuError> {
    source_swapping(name, &[])
}

/// The embedded source of `name` with its includes resolved, `swaps` naming the files
/// included instead of others.
pub fn source_swapping(name: &str, swaps: Swaps<'_>) -> Result<String, GpuError> {
    let lookup = |n: &str| {
        let n = swaps.iter().find(|(k, _)| *k == n).map_or(n, |(_, v)| *v);
        SOURCES
            .iter()
            .find(|(k, _)| *k == n)
            .map(|(_, v)| (*v).to_owned())
    };
    resolve(name, &lookup).map_err(|message| GpuError::Shader {
        name: name.into(),
        message,
    })
}

/// Resolves includes of `name` using `lookup` (embedded table or, in tests, the disk).
/// Each file is included at most once; a missing file is an error naming it.
pub fn resolve(name: &str, lookup: &dyn Fn(&str) -> Option<String>) -> Result<String, String> {
    let mut seen = Vec::new();
    let mut out = String::new();
    include(name, lookup, &mut seen, &mut out)?;
    Ok(out)
}

fn include(
    name: &str,
    lookup: &dyn Fn(&str) -> Option<String>,
    seen: &mut Vec<String>,
    out: &mut String,
) -> Result<(), String> {
    if seen.iter().any(|s| s == name) {
        return Ok(());
    }
    seen.push(name.to_owned());
    let text = lookup(name).ok_or_else(|| format!("included file {name} not found"))?;
    for line in text.lines() {
        match line.trim_start().strip_prefix(DIRECTIVE) {
            Some(dep) => include(dep.trim(), lookup, seen, out)?,
            None => {
                out.push_str(line);
                out.push('\n');
            }
        }
    }
    Ok(())
}

/// Creates a shader module from an embedded shader, failing on validation errors.
pub fn module(device: &wgpu::Device, name: &str) -> Result<wgpu::ShaderModule, GpuError> {
    module_swapping(device, name, &[])
}

/// The shader `name` with the includes `swaps` names resolved to other files (a storage
/// format chosen for the adapter, say).
pub fn module_swapping(
    device: &wgpu::Device,
    name: &str,
    swaps: Swaps<'_>,
) -> Result<wgpu::ShaderModule, GpuError> {
    let code = source_swapping(name, swaps)?;
    super::validated(device, name, || {
        device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(name),
            source: wgpu::ShaderSource::Wgsl(code.into()),
        })
    })
}

/// Several shader modules at once, in the order named.
pub fn modules<const N: usize>(
    device: &wgpu::Device,
    names: [&str; N],
) -> Result<[wgpu::ShaderModule; N], GpuError> {
    let built = names
        .iter()
        .map(|name| module(device, name))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(built
        .try_into()
        .unwrap_or_else(|_| unreachable!("one module per name")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn includes_resolve_once_and_missing_ones_fail() {
        let files = |n: &str| match n {
            "a.wgsl" => Some("//!include b.wgsl\n//!include c.wgsl\nfn a() {}".to_owned()),
            "b.wgsl" => Some("//!include c.wgsl\nfn b() {}".to_owned()),
            "c.wgsl" => Some("fn c() {}".to_owned()),
            "bad.wgsl" => Some("//!include nope.wgsl".to_owned()),
            _ => None,
        };
        let out = resolve("a.wgsl", &files).expect("resolves");
        assert_eq!(out.matches("fn c()").count(), 1);
        assert!(out.find("fn c()") < out.find("fn b()") && out.find("fn b()") < out.find("fn a()"));
        let err = resolve("bad.wgsl", &files).expect_err("missing include must fail");
        assert!(err.contains("nope.wgsl"), "{err}");
    }
}
