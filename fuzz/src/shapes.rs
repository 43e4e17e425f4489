//! The fuzzer's bytes as numbers, not text: a small scene — one or two quad lights, a receiving
//! parallelogram of any material and an occluding triangle — placed anywhere from 2⁻⁶⁰ to 2³⁰
//! scene units from the origin and from each other (raywave's coordinate limit, 10⁸, is about
//! 2²⁷), written as an OBJ file with its material
//! library. Text fuzzing rarely reaches the numerical hard cases (tiny or huge lights, far from
//! the origin, grazing, nearly degenerate); mutating the numbers themselves does.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Reads numbers from the fuzzer's bytes, zeros once they run out.
struct Numbers<'a>(&'a [u8]);

impl Numbers<'_> {
    fn byte(&mut self) -> u8 {
        let Some((&b, rest)) = self.0.split_first() else { return 0 };
        self.0 = rest;
        b
    }

    /// A number in [0, 1] (0 and 1 exactly included).
    fn unit(&mut self) -> f32 {
        f32::from(self.byte()) / 255.0
    }

    /// A vector whose components share one power-of-two scale in [2⁻⁶⁰, 2³⁰]: three 16-bit signed
    /// mantissas (each in [−1, 1)) and a scale byte.
    fn vector(&mut self) -> [f32; 3] {
        let mantissa = |n: &mut Self| f32::from(i16::from_le_bytes([n.byte(), n.byte()])) / 32768.0;
        let m = [mantissa(self), mantissa(self), mantissa(self)];
        let scale = 2f32.powi(i32::from(self.byte() % 91) - 60);
        m.map(|c| c * scale)
    }

    /// A point: `origin` plus a vector (the sum rounded as the scene file will hold it).
    fn point(&mut self, origin: [f32; 3]) -> [f32; 3] {
        add(origin, self.vector())
    }

    /// Emitted radiance: three components in [0, 1] times one power-of-two scale in [2⁻⁴⁰, 2⁵⁹]
    /// (the largest stays below raywave's limit of 10²⁰).
    fn radiance(&mut self) -> [f32; 3] {
        let c = [self.unit(), self.unit(), self.unit()];
        let scale = 2f32.powi(i32::from(self.byte() % 100) - 40);
        c.map(|c| c * scale)
    }
}

fn add(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// An OBJ file and its material library being written.
#[derive(Default)]
struct ObjWriter {
    obj: String,
    mtl: String,
    vertices: usize,
}

impl ObjWriter {
    /// An object of the given material from `corners` (1-based OBJ indices follow on), as one
    /// polygon per index list in `faces` (0-based into `corners`).
    fn object(&mut self, name: &str, material: &str, corners: &[[f32; 3]], faces: &[&[usize]]) {
        // `{:e}` writes the shortest text that reads back as the same `f32`.
        let _ = writeln!(self.obj, "o {name}\nusemtl {name}");
        for [x, y, z] in corners {
            let _ = writeln!(self.obj, "v {x:e} {y:e} {z:e}");
        }
        for face in faces {
            self.obj.push('f');
            for &i in *face {
                let _ = write!(self.obj, " {}", self.vertices + i + 1);
            }
            self.obj.push('\n');
        }
        self.vertices += corners.len();
        let _ = writeln!(self.mtl, "newmtl {name}\n{material}");
    }

    /// A parallelogram `corner + s·edge_u + t·edge_v` as two triangles sharing a diagonal, the
    /// way raywave recognizes an emissive mesh as a quad light.
    fn parallelogram(&mut self, name: &str, material: &str, corner: [f32; 3], edge_u: [f32; 3], edge_v: [f32; 3]) {
        let corners = [corner, add(corner, edge_u), add(add(corner, edge_u), edge_v), add(corner, edge_v)];
        self.object(name, material, &corners, &[&[0, 1, 2], &[0, 2, 3]]);
    }
}

/// Writes the scene `bytes` describe into `dir` (`shapes.obj` and `shapes.mtl`) and returns the
/// OBJ's path: a shared origin, a light, a receiver with its base colour, roughness and
/// metalness, an occluding triangle, and a second light if the next byte is odd.
pub fn write_shapes(dir: &Path, bytes: &[u8]) -> PathBuf {
    let mut n = Numbers(bytes);
    let mut scene = ObjWriter { obj: "mtllib shapes.mtl\n".into(), ..Default::default() };
    let origin = n.vector();
    let light = |n: &mut Numbers<'_>, scene: &mut ObjWriter, name: &str| {
        let [r, g, b] = n.radiance();
        let (corner, edge_u, edge_v) = (n.point(origin), n.vector(), n.vector());
        scene.parallelogram(name, &format!("Kd 0 0 0\nKe {r:e} {g:e} {b:e}"), corner, edge_u, edge_v);
    };
    light(&mut n, &mut scene, "light");
    let (base, roughness, metallic) = ([n.unit(), n.unit(), n.unit()], n.unit(), n.unit());
    let receiver = format!("Kd {} {} {}\nPr {roughness}\nPm {metallic}", base[0], base[1], base[2]);
    let (corner, edge_u, edge_v) = (n.point(origin), n.vector(), n.vector());
    scene.parallelogram("receiver", &receiver, corner, edge_u, edge_v);
    let occluder = [n.point(origin), n.point(origin), n.point(origin)];
    scene.object("occluder", "Kd 0.5 0.5 0.5", &occluder, &[&[0, 1, 2]]);
    if n.byte() % 2 == 1 {
        light(&mut n, &mut scene, "second_light");
    }
    std::fs::write(dir.join("shapes.mtl"), &scene.mtl).expect("the fuzz directory is writable");
    let path = dir.join("shapes.obj");
    std::fs::write(&path, &scene.obj).expect("the fuzz directory is writable");
    path
}
