//! Builds `raywave-kernels` to SPIR-V when the `vulkan` feature is on.
//!
//! `cargo-gpu-install` installs the toolchain rust-gpu 0.11 pins (through rustup) and compiles its
//! `rustc_codegen_spirv` backend once into the user cache (`~/.cache/rust-gpu`); the kernels are
//! then compiled by a separate cargo invocation on that toolchain, so this crate stays on stable.
//! One SPIR-V module is emitted per entry point, and `$OUT_DIR/kernels_spv.rs` embeds them all.

fn main() -> Result<(), Box<dyn std::error::Error>> {
    println!("cargo::rerun-if-changed=build.rs");
    #[cfg(feature = "vulkan")]
    spirv::build_kernels()?;
    Ok(())
}

#[cfg(feature = "vulkan")]
mod spirv {
    use cargo_gpu_install::install::Install;
    use cargo_gpu_install::spirv_builder::{Capability, ModuleResult, SpirvMetadata};
    use std::fmt::Write as _;
    use std::path::PathBuf;

    /// SPIR-V target: Vulkan 1.2 gives SPIR-V 1.5, which `SPV_KHR_ray_query` needs (≥ 1.4).
    const TARGET: &str = "spirv-unknown-vulkan1.2";

    /// Cargo's setting for what its resolver does with versions whose `rust-version` the
    /// toolchain does not meet (`resolver.incompatible-rust-versions`, Cargo 1.84+).
    const MSRV_RESOLVER: &str = "CARGO_RESOLVER_INCOMPATIBLE_RUST_VERSIONS";

    /// One SPIR-V build of the kernels: the capabilities it enables and its own target dir (so
    /// the variants do not invalidate each other's incremental state).
    struct Variant {
        name: &'static str,
        capabilities: &'static [Capability],
        extensions: &'static [&'static str],
        /// Features of `raywave-kernels` that expose the variant's entry points (`ray-query` and
        /// `ray-tracing` imply `entry-points`, the compute kernels every variant emits).
        features: &'static [&'static str],
    }

    /// Kernels that need no ray-tracing capability come from `base`, so they run on every Vulkan
    /// 1.2 device; entry points behind the kernels' `ray-query` and `ray-tracing` features come from
    /// the variant that enables them.
    const VARIANTS: &[Variant] = &[
        Variant { name: "base", capabilities: &[], extensions: &[], features: &["entry-points"] },
        Variant {
            name: "ray-query",
            capabilities: &[Capability::RayQueryKHR],
            extensions: &["SPV_KHR_ray_query"],
            features: &["ray-query"],
        },
        Variant {
            name: "ray-tracing",
            capabilities: &[Capability::RayTracingKHR],
            extensions: &["SPV_KHR_ray_tracing"],
            features: &["ray-tracing"],
        },
    ];

    pub fn build_kernels() -> Result<(), Box<dyn std::error::Error>> {
        let manifest_dir = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR")?);
        let kernels = manifest_dir.join("..").join("kernels").canonicalize()?;
        // Relative to this package's root, which cargo resolves against the checkout being built:
        // an absolute path would tie the shared build cache (`.ci/run`'s `$RAYWAVE_CACHE`) to the
        // checkout that last ran this script, and a second checkout's kernel edits would keep
        // that checkout's stale SPIR-V.
        println!("cargo::rerun-if-changed=../kernels");
        println!("cargo::rerun-if-changed=../shared");

        // The codegen backend is built from crates.io without a lock file: cargo-gpu-install 0.11
        // deletes the one its metadata query wrote, then runs `cargo +<pinned nightly> build`,
        // which passes this variable on. With it that cargo resolves each dependency to its
        // newest version whose `rust-version` the pinned nightly meets (cargo's MSRV-aware
        // resolver, falling back to `rustc -V` where no `rust-version` is set), so a release
        // that needs a newer compiler cannot break a first build. Unset, it resolved the same
        // 127 packages on 2026-12-02. A value set in the environment is kept; set here, it
        // overrides a user's `resolver.incompatible-rust-versions` in Cargo's config. It also
        // reaches the metadata query that picks the codegen's version (on the stable toolchain)
        // and spirv-builder's builds of the kernels (whose lock file is committed): were a
        // `rustc_codegen_spirv` 0.11 release to need a newer compiler than this stable one, the
        // query would keep an older 0.11 and the backend build could take the newer.
        if std::env::var_os(MSRV_RESOLVER).is_none() {
            std::env::set_var(MSRV_RESOLVER, "fallback");
        }
        let backend = Install::from_shader_crate(kernels.clone()).within_build_script().run()?;
        // Entry point name → module path, each from the first (leanest) variant that emits it.
        let mut modules = std::collections::BTreeMap::new();
        for variant in VARIANTS {
            let mut builder = backend.to_spirv_builder(&kernels, TARGET);
            builder.release = true;
            builder.multimodule = true;
            // A warning in the kernels fails the build, as `clippy -D warnings` does for the host.
            builder.deny_warnings = true;
            builder.spirv_metadata = SpirvMetadata::NameVariables;
            // Every entry point declares the `SignedZeroInfNanPreserve` execution mode (IEEE Inf
            // and NaN kept: `raywave-kernels`' entry module).
            builder.capabilities.push(Capability::SignedZeroInfNanPreserve);
            builder.capabilities.extend_from_slice(variant.capabilities);
            builder.extensions.extend(variant.extensions.iter().map(|e| e.to_string()));
            builder.shader_crate_features.features = variant.features.iter().map(|f| f.to_string()).collect();
            builder.target_dir_path = Some(PathBuf::from(format!("spirv-builder/{}", variant.name)));
            let ModuleResult::MultiModule(built) = builder.build()?.module else {
                return Err("expected one SPIR-V module per entry point".into());
            };
            for (entry, path) in built {
                modules.entry(entry).or_insert(path);
            }
        }

        let mut source = String::from("// Generated by host/build.rs: the SPIR-V modules of raywave-kernels.\n");
        writeln!(source, "/// Every emitted module as (entry point, SPIR-V bytes).")?;
        writeln!(source, "pub const MODULES: &[(&str, &[u8])] = &[")?;
        for (entry, path) in &modules {
            writeln!(source, "    ({entry:?}, include_bytes!({:?})),", path.display().to_string())?;
        }
        writeln!(source, "];")?;
        let out = PathBuf::from(std::env::var("OUT_DIR")?).join("kernels_spv.rs");
        std::fs::write(out, source)?;
        Ok(())
    }
}
