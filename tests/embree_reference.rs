//! Embree 3 (feature `embree`) agrees with raywave's CPU trace on the same rays: the reference
//! the benchmark compares against must compute the same thing.
#![cfg(feature = "embree")]

use raywave::cpu::{self, CpuScene};
use raywave::embree::EmbreeScene;
use raywave::frame::generate_params;
use raywave::kernels::trace::Ray;
use raywave::scene::procedural::hairball;
use raywave::shared::stream::NO_HIT;
use raywave::Scene;

#[test]
fn embree_matches_the_cpu_trace() {
    let (meshes, camera) = hairball(20_000, 5).expect("a hairball");
    for scene in [Scene::load("builtin:cornell").unwrap(), Scene::new("hairball", meshes, camera).unwrap()] {
        let rays = cpu::generate(&generate_params(&scene, 256, 256, 1)).expect("generate");
        let cpu_scene = CpuScene::build(&scene).unwrap();
        let expected = cpu::trace(&cpu_scene, &rays).expect("trace");
        let embree = EmbreeScene::build(&scene).unwrap();
        let mut agree = 0;
        for i in 0..rays.len() {
            let ray = Ray::from_stream(rays.origin[i], rays.direction[i]);
            let hit = embree.closest_hit(&ray);
            assert_eq!(embree.occluded(&ray), expected.primitive[i] != NO_HIT, "{}: ray {i}", scene.name());
            if (hit.instance, hit.primitive) == (expected.instance[i], expected.primitive[i]) {
                agree += 1;
                if hit.primitive != NO_HIT {
                    assert!((hit.t - expected.t[i]).abs() <= 1e-5 * expected.t[i], "{}: ray {i}", scene.name());
                }
            }
        }
        assert!(agree as f64 >= 0.9999 * rays.len() as f64, "{}: {agree} of {} agree", scene.name(), rays.len());
    }
}
