//! The SPIR-V modules of `raywave-kernels`, embedded at build time (one per entry point), and the
//! edits the host makes to them before a driver sees them: every float sum and product marked
//! `NoContraction` ([`without_contraction`]), and another workgroup size for a 1-D compute stage.

use crate::error::{Error, Result};
use raywave_shared::bindings::WORKGROUP_SIZE;
use rspirv::binary::Assemble;
use rspirv::dr::{Instruction, Operand};
use rspirv::spirv::{BuiltIn, Decoration, ExecutionMode, Op};

include!(concat!(env!("OUT_DIR"), "/kernels_spv.rs"));

/// The SPIR-V bytes of entry point `entry`.
pub fn module(entry: &str) -> Result<&'static [u8]> {
    MODULES
        .iter()
        .find(|(name, _)| *name == entry)
        .map(|(_, bytes)| *bytes)
        .ok_or_else(|| embedded_error(entry, "no module for this entry point"))
}

/// The SPIR-V words of entry point `entry` as raywave's Vulkan backend hands them to the driver:
/// [`without_contraction`]; with `local_size_x`, a compute entry point's `LocalSize` execution
/// mode set to `(local_size_x, 1, 1)` in place of the `(WORKGROUP_SIZE, 1, 1)` it was compiled
/// with (`threads(64)`), so that the pipeline runs workgroups of that many invocations. Only
/// stages whose code does not depend on the size may be given one (every 1-D stream stage:
/// `raywave_shared::bindings::stream_index`); the kernel must not also carry a `WorkgroupSize`
/// built-in, which would override the execution mode.
pub fn words(entry: &str, local_size_x: Option<u32>) -> Result<Vec<u32>> {
    let fail = |reason: &str| embedded_error(entry, reason);
    let mut module = rspirv::dr::load_bytes(module(entry)?).map_err(|e| fail(&e.to_string()))?;
    forbid_contraction(&mut module);
    match local_size_x {
        None | Some(WORKGROUP_SIZE) => {}
        Some(x) => set_local_size_x(&mut module, entry, x)?,
    }
    Ok(module.assemble())
}

/// The float arithmetic a Vulkan driver may combine with other instructions unless the result
/// is decorated `NoContraction` — a product and the sum it feeds into one fused multiply–add,
/// most often (SPIR-V specification, "NoContraction"; NVIDIA's driver fused the triangle test's
/// edge products on an H100, `raywave_kernels::triangle`).
const CONTRACTIBLE: [Op; 9] = [
    Op::FAdd,
    Op::FSub,
    Op::FMul,
    Op::FDiv,
    Op::VectorTimesScalar,
    Op::MatrixTimesScalar,
    Op::VectorTimesMatrix,
    Op::MatrixTimesVector,
    Op::Dot,
];

/// `code`, a SPIR-V module, with the result of every float sum, difference, product and quotient
/// decorated `NoContraction`, so that a driver evaluates each as written, rounded on its own, as
/// the CPU build of the same Rust does (Rust never fuses `a * b + c`). rust-gpu cannot emit the
/// decoration, and without it a driver may fuse a product into the sum that uses it: the
/// watertight triangle test's vertex transform (`raywave_kernels::triangle`) must round the same
/// vertex alike in every triangle that shares it, and the denoiser's noise-line taps
/// (`raywave_kernels::denoise::noise`) must land on the CPU's pixels. raywave's Vulkan backend
/// loads every kernel so ([`words`]); an engine that builds the kernels into its own shaders
/// passes its modules through this for the same arithmetic. A module that does not parse is
/// [`Error::InvalidParameter`].
pub fn without_contraction(code: &[u32]) -> Result<Vec<u32>> {
    let mut module = rspirv::dr::load_words(code)
        .map_err(|e| Error::InvalidParameter { name: "code", reason: format!("not a SPIR-V module: {e}") })?;
    forbid_contraction(&mut module);
    Ok(module.assemble())
}

/// Decorates every [`CONTRACTIBLE`] result in `module` `NoContraction`, once each.
fn forbid_contraction(module: &mut rspirv::dr::Module) {
    let decorated: std::collections::HashSet<u32> = no_contraction_targets(module).collect();
    let undecorated: Vec<u32> = module
        .functions
        .iter()
        .flat_map(|function| &function.blocks)
        .flat_map(|block| &block.instructions)
        .filter(|i| CONTRACTIBLE.contains(&i.class.opcode))
        .filter_map(|i| i.result_id)
        .filter(|id| !decorated.contains(id))
        .collect();
    let no_contraction = Operand::Decoration(Decoration::NoContraction);
    module.annotations.extend(
        undecorated
            .into_iter()
            .map(|id| Instruction::new(Op::Decorate, None, None, vec![Operand::IdRef(id), no_contraction.clone()])),
    );
}

/// The ids `module` decorates `NoContraction`, in its order (with repeats, if it repeats one).
fn no_contraction_targets(module: &rspirv::dr::Module) -> impl Iterator<Item = u32> + '_ {
    let no_contraction = Operand::Decoration(Decoration::NoContraction);
    module
        .annotations
        .iter()
        .filter(move |i| i.class.opcode == Op::Decorate && i.operands.get(1) == Some(&no_contraction))
        .filter_map(|i| match i.operands.first() {
            Some(&Operand::IdRef(target)) => Some(target),
            _ => None,
        })
}

/// Sets entry point `entry`'s `LocalSize` x in `module` from `WORKGROUP_SIZE` to `x`.
fn set_local_size_x(module: &mut rspirv::dr::Module, entry: &str, x: u32) -> Result<()> {
    let fail = |reason: &str| embedded_error(entry, reason);
    let is_entry = |i: &Instruction| matches!(i.operands.get(2), Some(Operand::LiteralString(name)) if name == entry);
    let function = match module.entry_points.iter().find(|i| is_entry(i)).map(|i| &i.operands[1]) {
        Some(&Operand::IdRef(id)) => id,
        _ => return Err(fail("no OpEntryPoint of this name")),
    };
    let sets_workgroup_size = |i: &Instruction| {
        i.class.opcode == Op::Decorate
            && i.operands.get(1) == Some(&Operand::Decoration(Decoration::BuiltIn))
            && i.operands.get(2) == Some(&Operand::BuiltIn(BuiltIn::WorkgroupSize))
    };
    if module.annotations.iter().any(sets_workgroup_size) {
        return Err(fail("a WorkgroupSize built-in fixes the workgroup size"));
    }
    let local_size = module.execution_modes.iter_mut().find(|i| {
        i.operands.first() == Some(&Operand::IdRef(function))
            && i.operands.get(1) == Some(&Operand::ExecutionMode(ExecutionMode::LocalSize))
    });
    let compiled = [WORKGROUP_SIZE, 1, 1].map(Operand::LiteralBit32);
    match local_size {
        Some(mode) if mode.operands[2..] == compiled => mode.operands[2] = Operand::LiteralBit32(x),
        Some(mode) => return Err(fail(&format!("compiled with LocalSize {:?}, not (64, 1, 1)", &mode.operands[2..]))),
        None => return Err(fail("no LocalSize execution mode")),
    }
    Ok(())
}

fn embedded_error(entry: &str, reason: &str) -> Error {
    Error::Vulkan { call: "embedded SPIR-V", result: format!("{entry}: {reason}") }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `LocalSize` operands of `entry` in `code`.
    fn local_size(code: &[u32], entry: &str) -> Vec<Operand> {
        let module = rspirv::dr::load_words(code).expect("parses");
        let is_local_size =
            |i: &&Instruction| i.operands.get(1) == Some(&Operand::ExecutionMode(ExecutionMode::LocalSize));
        module.execution_modes.iter().find(is_local_size).expect(entry).operands[2..].to_vec()
    }

    /// `code` with `entry`'s LocalSize x changed from `from` to `to` (the test's way back).
    fn with_local_size_x_from(code: &[u32], entry: &str, from: u32, to: u32) -> Vec<u32> {
        let mut module = rspirv::dr::load_words(code).expect("parses");
        for mode in &mut module.execution_modes {
            if mode.operands.get(1) == Some(&Operand::ExecutionMode(ExecutionMode::LocalSize)) {
                assert_eq!(mode.operands[2], Operand::LiteralBit32(from), "{entry}");
                mode.operands[2] = Operand::LiteralBit32(to);
            }
        }
        module.assemble()
    }

    #[test]
    fn another_workgroup_size_changes_only_the_local_size() {
        let entry = "entry::trace_cwbvh";
        let compiled = words(entry, None).expect("embedded");
        assert_eq!(local_size(&compiled, entry), [64, 1, 1].map(Operand::LiteralBit32));
        assert_eq!(words(entry, Some(WORKGROUP_SIZE)).expect("unchanged"), compiled);
        let patched = words(entry, Some(256)).expect("patched");
        assert_eq!(local_size(&patched, entry), [256, 1, 1].map(Operand::LiteralBit32));
        // Everything else re-assembles to the same words: changing the operand back restores the
        // module.
        assert_eq!(with_local_size_x_from(&patched, entry, 256, WORKGROUP_SIZE), compiled);
    }

    /// The shade module declares the switch [`super::super::backend`] builds its pipelines with:
    /// a `u32` specialization constant of id `RESIDUAL_CODE_SPEC_ID` and default 1 (the residual
    /// kept, as `ShadeParams::analytic_residual` asks). Vulkan sets only the constants a module
    /// declares, so an id out of step would go unnoticed, and every pass would compile the
    /// residual's code.
    #[test]
    fn the_shade_module_declares_its_residual_switch() {
        use raywave_shared::bindings::shade::RESIDUAL_CODE_SPEC_ID;
        let module = rspirv::dr::load_words(words("entry::shade", None).expect("embedded")).expect("parses");
        let spec_ids: Vec<(Operand, Operand)> = module
            .annotations
            .iter()
            .filter(|i| i.class.opcode == Op::Decorate && i.operands[1] == Operand::Decoration(Decoration::SpecId))
            .map(|i| (i.operands[0].clone(), i.operands[2].clone()))
            .collect();
        let [(Operand::IdRef(constant), id)] = spec_ids.as_slice() else { panic!("one SpecId: {spec_ids:?}") };
        assert_eq!(*id, Operand::LiteralBit32(RESIDUAL_CODE_SPEC_ID));
        let declared = module.types_global_values.iter().find(|i| i.result_id == Some(*constant)).expect("declared");
        assert_eq!(
            (declared.class.opcode, declared.operands.as_slice()),
            (Op::SpecConstant, &[Operand::LiteralBit32(1)][..])
        );
    }

    /// Every module declares, for its entry point, the `SignedZeroInfNanPreserve` execution mode
    /// for 32-bit floats (and its capability): without it a Vulkan driver may assume that no
    /// float is NaN or ±Inf and fold the kernels' checks for them (`raywave_kernels::entry`).
    #[test]
    fn every_module_keeps_ieee_inf_and_nan() {
        use rspirv::spirv::Capability;
        assert!(MODULES.len() >= 20, "{} modules", MODULES.len());
        for (entry, bytes) in MODULES {
            let module = rspirv::dr::load_bytes(bytes).expect("parses");
            let capability = Operand::Capability(Capability::SignedZeroInfNanPreserve);
            assert!(module.capabilities.iter().any(|i| i.operands[0] == capability), "{entry}: no capability");
            let [entry_point] = module.entry_points.as_slice() else { panic!("{entry}: one entry point") };
            let keeps = module.execution_modes.iter().any(|i| {
                i.operands[..]
                    == [
                        entry_point.operands[1].clone(),
                        Operand::ExecutionMode(ExecutionMode::SignedZeroInfNanPreserve),
                        Operand::LiteralBit32(32),
                    ]
            });
            assert!(keeps, "{entry}: no SignedZeroInfNanPreserve 32");
        }
    }

    /// The shade module stays within its size budget. Lavapipe compiles a pipeline at its first
    /// dispatch, with LLVM on one thread, in a time that grows with the module, and a newcomer's
    /// first Vulkan render waits for it (README, Shading: at 634 KB the compile took 38.5 s on this
    /// project's 2-vCPU VM; at 350 KB 6–8 s, 10–15 s with the residual; at 361.6 KB, with the
    /// light choice's quad bounds and uniform share, the first render's shade stage took
    /// 7.6–10.4 s against 8.0–10.3 s at 352.0 KB, six alternating runs each; at 365.0 KB, with
    /// near-rectangles sampled exactly, 6.7–8.1 s against 7.3–9.8 s at 363.0 KB, four and three
    /// alternating runs; at 372.3 KB, with the `SignedZeroInfNanPreserve` capability — which
    /// stops spirv-opt's float folds that assume no NaN or Inf — 7.5–10.2 s against 8.0–8.9 s at
    /// 365.4 KB, four and three runs). rust-gpu inlines every call, so a second call site of a
    /// large function grows the module, and the mesa shader cache hides the cost from every later
    /// run. Raise the budget only with the compile measured (`MESA_SHADER_CACHE_DISABLE=true
    /// raywave render --device vulkan`).
    #[test]
    fn the_shade_module_stays_within_its_size_budget() {
        const BUDGET_BYTES: usize = 373_000;
        let bytes = module("entry::shade").expect("embedded").len();
        assert!(bytes <= BUDGET_BYTES, "the shade module is {bytes} bytes, over its budget of {BUDGET_BYTES}");
    }

    /// Every module the backend loads has each float sum, difference, product and quotient
    /// decorated `NoContraction` exactly once, and nothing else: the embedded module (rust-gpu
    /// emits no such decoration) plus one `OpDecorate` per such result: over 4 000 in the shade
    /// module, over 100 in the trace and noise ones. Decorating a decorated module changes nothing.
    #[test]
    fn every_float_sum_and_product_is_marked_no_contraction() {
        for (entry, bytes) in MODULES {
            let embedded = rspirv::dr::load_bytes(bytes).expect("parses");
            assert_eq!(no_contraction_targets(&embedded).count(), 0, "{entry}: rust-gpu decorated");
            let loaded_words = words(entry, None).expect("embedded");
            let loaded = rspirv::dr::load_words(&loaded_words).expect("parses");
            let mut arithmetic: Vec<u32> = loaded
                .functions
                .iter()
                .flat_map(|function| &function.blocks)
                .flat_map(|block| &block.instructions)
                .filter(|i| CONTRACTIBLE.contains(&i.class.opcode))
                .map(|i| i.result_id.expect("a result"))
                .collect();
            let mut decorated: Vec<u32> = no_contraction_targets(&loaded).collect();
            arithmetic.sort_unstable();
            decorated.sort_unstable();
            assert_eq!(decorated, arithmetic, "{entry}");
            let least = match *entry {
                "entry::shade" => 4000,
                "entry::trace_cwbvh" | "entry::denoise_noise" => 100,
                _ => 0,
            };
            assert!(arithmetic.len() >= least, "{entry}: {} float operations", arithmetic.len());
            let mut undecorated = loaded.clone();
            undecorated.annotations.truncate(embedded.annotations.len());
            assert_eq!(undecorated.assemble(), embedded.assemble(), "{entry}: more than decorations added");
            assert_eq!(without_contraction(&loaded_words).expect("parses"), loaded_words, "{entry}: twice");
        }
    }

    #[test]
    fn without_contraction_refuses_what_is_not_spir_v() {
        let refused = without_contraction(&[0x0723_0203, 1, 2]).expect_err("not a module");
        assert!(matches!(refused, Error::InvalidParameter { name: "code", .. }), "{refused}");
    }

    #[test]
    fn a_module_without_the_compiled_local_size_is_refused() {
        // A ray-generation shader has no LocalSize.
        assert!(matches!(words("entry::trace_raygen", Some(128)), Err(Error::Vulkan { .. })));
        let compiled = words("entry::generate", None).expect("embedded");
        let other = with_local_size_x_from(&compiled, "entry::generate", 64, 32);
        let set = |code: &[u32], entry: &str| {
            set_local_size_x(&mut rspirv::dr::load_words(code).expect("parses"), entry, 128)
        };
        let refused = set(&other, "entry::generate").expect_err("compiled size differs");
        assert!(refused.to_string().contains("not (64, 1, 1)"), "{refused}");
        assert!(matches!(set(&compiled, "entry::nothing"), Err(Error::Vulkan { .. })));
    }
}
