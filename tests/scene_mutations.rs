//! Malformed scene files end in a scene or a typed error, never a panic or a hang: fixed-seed
//! random mutations of the valid test scene `tests/data/emissive_quad.gltf` — numbers in its JSON
//! replaced by edge values, bytes of its text overwritten, the same scene as a `.glb` container
//! with bytes overwritten — and of a small `.obj` and of an `.obj`'s material library, each loaded
//! with `Scene::load`; whatever loads also has its BVH built by the CPU backend.
//!
//! Before the glTF loader's own checks, mutations like these panicked inside the `gltf` crate
//! (an out-of-range POSITION accessor, float indices), hung (node cycles) or aborted on a huge
//! allocation (a sparse accessor's count).

use raywave::cpu::CpuBackend;
use raywave::{Backend, Scene};
use serde_json::Value;

/// Mutations per kind.
const MUTATIONS: usize = 300;

/// xorshift64*: a reproducible stream of mutation choices.
struct Rng(u64);

impl Rng {
    fn below(&mut self, n: usize) -> usize {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 33) as usize % n
    }
}

/// How many mutated files loaded and how many were rejected.
#[derive(Debug, Default)]
struct Outcomes {
    loaded: usize,
    rejected: usize,
}

impl Outcomes {
    /// Writes `bytes` as `name` in `dir` and loads it; a panic fails the test right there.
    fn load(&mut self, dir: &std::path::Path, name: &str, bytes: &[u8]) {
        let path = dir.join(name);
        std::fs::write(&path, bytes).unwrap();
        match Scene::load(path.to_str().unwrap()) {
            Ok(scene) => {
                // What loads must also build: coordinates the loader once accepted (from about
                // 10¹⁹ on, e.g. a finite node scale of 10³⁰) panicked in obvhs' CWBVH build.
                CpuBackend::new().load_scene(&scene).unwrap();
                self.loaded += 1;
            }
            Err(err) => {
                assert!(!err.to_string().is_empty());
                self.rejected += 1;
            }
        }
    }

    /// Both outcomes occurred, so the mutations reach past the parser and also break files.
    fn assert_mixed(&self, kind: &str) {
        assert!(self.loaded > 0 && self.rejected > 0, "{kind}: {self:?}");
    }
}

fn base_gltf() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/data/emissive_quad.gltf")).unwrap()
}

/// JSON pointers to every number in `value`.
fn number_pointers(value: &Value, pointer: String, out: &mut Vec<String>) {
    match value {
        Value::Number(_) => out.push(pointer),
        Value::Array(items) => {
            items.iter().enumerate().for_each(|(i, item)| number_pointers(item, format!("{pointer}/{i}"), out))
        }
        Value::Object(fields) => fields.iter().for_each(|(key, item)| {
            let key = key.replace('~', "~0").replace('/', "~1");
            number_pointers(item, format!("{pointer}/{key}"), out)
        }),
        _ => {}
    }
}

#[test]
fn gltf_numbers_replaced_by_edge_values_load_or_are_errors() {
    const EDGES: [&str; 18] = [
        "-1",
        "0",
        "1",
        "2",
        "3",
        "7",
        "36",
        "5121",
        "5126",
        "4294967295",
        "4294967296",
        "18446744073709551615",
        "3.5",
        "1e19",
        "1e30",
        "1e38",
        "-1e-30",
        "1e300",
    ];
    let base: Value = serde_json::from_str(&base_gltf()).unwrap();
    let mut pointers = Vec::new();
    number_pointers(&base, String::new(), &mut pointers);
    let dir = tempfile::tempdir().unwrap();
    let (mut rng, mut outcomes) = (Rng(0x9e37_79b9_7f4a_7c15), Outcomes::default());
    for _ in 0..MUTATIONS {
        let mut value = base.clone();
        for _ in 0..=rng.below(3) {
            let pointer = &pointers[rng.below(pointers.len())];
            *value.pointer_mut(pointer).unwrap() = serde_json::from_str(EDGES[rng.below(EDGES.len())]).unwrap();
        }
        outcomes.load(dir.path(), "mutated.gltf", value.to_string().as_bytes());
    }
    outcomes.assert_mixed("JSON numbers");
}

/// Overwrites 1 to 4 random bytes of `bytes` with bytes from `alphabet`.
fn overwrite_bytes(rng: &mut Rng, bytes: &[u8], alphabet: &[u8]) -> Vec<u8> {
    let mut mutated = bytes.to_vec();
    for _ in 0..=rng.below(4) {
        let at = rng.below(mutated.len());
        mutated[at] = alphabet[rng.below(alphabet.len())];
    }
    mutated
}

#[test]
fn gltf_text_and_glb_with_overwritten_bytes_load_or_are_errors() {
    let text = base_gltf();
    // A GLB of the same scene: 12-byte header and one JSON chunk padded with spaces (its buffer
    // keeps the embedded data URI, which GLB allows).
    let mut json = text.clone().into_bytes();
    json.resize(json.len().next_multiple_of(4), b' ');
    let mut glb = Vec::new();
    glb.extend_from_slice(b"glTF");
    glb.extend_from_slice(&2u32.to_le_bytes());
    glb.extend_from_slice(&(12 + 8 + json.len() as u32).to_le_bytes());
    glb.extend_from_slice(&(json.len() as u32).to_le_bytes());
    glb.extend_from_slice(b"JSON");
    glb.extend_from_slice(&json);
    let dir = tempfile::tempdir().unwrap();
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    let (mut text_outcomes, mut glb_outcomes) = (Outcomes::default(), Outcomes::default());
    glb_outcomes.load(dir.path(), "unmutated.glb", &glb);
    assert_eq!(glb_outcomes.loaded, 1, "the GLB container is valid");
    let all_bytes: Vec<u8> = (0..=255).collect();
    for _ in 0..MUTATIONS {
        text_outcomes.load(
            dir.path(),
            "mutated.gltf",
            &overwrite_bytes(&mut rng, text.as_bytes(), b"0123456789-,.[]{}\"e"),
        );
        // Half the GLB mutations hit the 20 header and chunk-header bytes.
        let mutated = if rng.below(2) == 0 {
            let mut mutated = glb.clone();
            mutated[rng.below(20)] = all_bytes[rng.below(256)];
            mutated
        } else {
            overwrite_bytes(&mut rng, &glb, &all_bytes)
        };
        glb_outcomes.load(dir.path(), "mutated.glb", &mutated);
    }
    text_outcomes.assert_mixed("glTF text bytes");
    glb_outcomes.assert_mixed("GLB bytes");
}

#[test]
fn obj_with_overwritten_bytes_loads_or_is_an_error() {
    let obj =
        b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\nvt 0 0\ng a\nf 1/1/1 2/1/1 3/1/1\nf 2 4 3\no b\nf -1 -2 -3\n";
    let dir = tempfile::tempdir().unwrap();
    let (mut rng, mut outcomes) = (Rng(0x1234_5678_9abc_def1), Outcomes::default());
    for _ in 0..MUTATIONS {
        outcomes.load(dir.path(), "mutated.obj", &overwrite_bytes(&mut rng, obj, b"0123456789-/ .\nfvne"));
    }
    outcomes.assert_mixed("OBJ bytes");
}

/// The material library of an OBJ scene with bytes overwritten: before the loader checked each
/// colour's three numbers, a `Kd` or `Ke` line cut short panicked inside tobj.
#[test]
fn mtl_with_overwritten_bytes_loads_or_is_an_error() {
    let obj = b"mtllib scene.mtl\nv 0 0 0\nv 1 0 0\nv 1 0 1\nv 0 0 1\nv 0 1 0\n\
                o lamp\nusemtl lamp\nf 4 3 2 1\no floor\nusemtl floor\nf 1 2 5\n";
    let mtl = b"newmtl floor\nKd 0.5 0.25 1\nKa 0 0 0\nKs 1 1 1\nNs 198\nPr 0.5\nPm 0\n\
                newmtl lamp\nKd 0 0 0\nKe 4 2 1\n";
    let dir = tempfile::tempdir().unwrap();
    let (mut rng, mut outcomes) = (Rng(0x0bad_5eed_0bad_5eed), Outcomes::default());
    for _ in 0..MUTATIONS {
        std::fs::write(dir.path().join("scene.mtl"), overwrite_bytes(&mut rng, mtl, b"0123456789-. \nKdaesNPrm"))
            .unwrap();
        outcomes.load(dir.path(), "mutated.obj", obj);
    }
    outcomes.assert_mixed("MTL bytes");
}
