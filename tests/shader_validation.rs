//! Every shaders/*.wgsl parses and validates with naga, and every one is embedded.
//! All failures are reported at once.

use std::path::PathBuf;
use volao::gpu::shaders;

fn shader_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("shaders")
}

fn on_disk() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(shader_dir())
        .expect("shaders/ exists")
        .filter_map(|e| e.ok())
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".wgsl"))
        .collect();
    names.sort();
    names
}

/// Where a shader's includes come from.
type Lookup<'a> = dyn Fn(&str) -> Option<String> + 'a;

#[test]
fn every_shader_validates_with_naga() {
    let names = on_disk();
    assert!(!names.is_empty(), "no shaders found");
    let lookup = |n: &str| std::fs::read_to_string(shader_dir().join(n)).ok();
    let mut failures = Vec::new();
    // Fragments (`//!fragment` on the first line) use their includer's declarations:
    // each is validated inside the shaders that include it, and one must.
    let fragment = |n: &str| lookup(n).is_some_and(|s| s.starts_with("//!fragment"));
    for name in names.iter().filter(|n| fragment(n)) {
        let included = names
            .iter()
            .any(|other| lookup(other).is_some_and(|s| s.contains(&format!("//!include {name}"))));
        if !included {
            failures.push(format!("{name}: a fragment no shader includes"));
        }
    }
    // Each shader as it is, and with CAO's volumes in R32Float (the include ao::cao
    // swaps on adapters that cannot write R16Float).
    let r32 = |n: &str| match n {
        "cao_format.wgsl" => lookup("cao_format_r32.wgsl"),
        n => lookup(n),
    };
    let variants: [(&str, &Lookup); 2] = [("", &lookup), (" (R32Float)", &r32)];
    let shaders = names.iter().filter(|n| !fragment(n));
    for (name, (variant, lookup)) in shaders.flat_map(|n| variants.iter().map(move |v| (n, v))) {
        let name = &format!("{name}{variant}");
        let file = name.trim_end_matches(variant);
        let source = match shaders::resolve(file, lookup) {
            Ok(s) => s,
            Err(e) => {
                failures.push(format!("{name}: {e}"));
                continue;
            }
        };
        let module = match naga::front::wgsl::parse_str(&source) {
            Ok(m) => m,
            Err(e) => {
                failures.push(format!(
                    "{name}: parse error:\n{}",
                    e.emit_to_string(&source)
                ));
                continue;
            }
        };
        let mut validator = naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::all(),
        );
        if let Err(e) = validator.validate(&module) {
            failures.push(format!(
                "{name}: validation error:\n{}",
                e.emit_to_string(&source)
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{} shader(s) failed:\n{}",
        failures.len(),
        failures.join("\n\n")
    );
}

#[test]
fn every_shader_on_disk_is_embedded_and_identical() {
    for name in on_disk() {
        let embedded = shaders::SOURCES.iter().find(|(n, _)| *n == name);
        let disk = std::fs::read_to_string(shader_dir().join(&name)).expect("read");
        match embedded {
            Some((_, text)) => assert_eq!(*text, disk, "{name}: embedded copy is stale"),
            None => panic!("{name} is in shaders/ but not in gpu::shaders::SOURCES"),
        }
    }
}
