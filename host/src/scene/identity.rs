//! Which [`Scene`](super::Scene) value a backend loaded and a [`ShadeData`] was built from, so that
//! a backend can refuse shade data of another scene (a trace against new geometry shaded with old
//! triangles and materials had returned a wrong image with `Ok`).
//!
//! [`ShadeData`]: crate::shading::ShadeData

use std::fmt;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// The identity of one built [`Scene`](super::Scene): a serial number unique in the process, given
/// by [`Scene::new`](super::Scene::new) (through which every loader builds its scene), and the
/// scene's name for messages. Clones of a scene keep it: they hold the same geometry and
/// materials, and a `Scene` has no method that changes them after it is built. Scenes built
/// apart — the same file loaded twice, an engine's scene rebuilt after it moved an object — get
/// different identities, even with equal contents (which `Scene`'s `==` compares).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SceneIdentity {
    /// Unique per built scene, from 0 in build order.
    serial: u64,
    /// The scene's name ([`Scene::name`](super::Scene::name)).
    name: Arc<str>,
}

impl SceneIdentity {
    /// A new identity, unique in the process, for a scene named `name`.
    pub(super) fn new(name: &str) -> Self {
        static SERIAL: AtomicU64 = AtomicU64::new(0);
        Self { serial: SERIAL.fetch_add(1, Ordering::Relaxed), name: name.into() }
    }

    /// The scene's name (a file path or `builtin:NAME`).
    pub fn name(&self) -> &str {
        &self.name
    }
}

impl fmt::Display for SceneIdentity {
    /// `NAME (scene #SERIAL)`: the serial tells apart two builds of one file.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{} (scene #{})", self.name, self.serial)
    }
}

#[cfg(test)]
mod tests {
    use crate::scene::Scene;

    /// A clone is the same scene; two builds of one scene are not, though their contents (which
    /// `==` compares) are equal, and a build with an object moved differs in both.
    #[test]
    fn clones_share_an_identity_and_separate_builds_do_not() {
        let scene = Scene::load("builtin:cornell").unwrap();
        let again = Scene::load("builtin:cornell").unwrap();
        assert_eq!(scene.clone().identity(), scene.identity());
        assert_ne!(again.identity(), scene.identity());
        assert_eq!(again, scene, "equal contents");
        let (_, moved) = crate::scene::tests::cornell_and_moved();
        assert_ne!(moved.identity(), scene.identity());
        assert_ne!(moved, scene);
        let text = moved.identity().to_string();
        assert!(text.starts_with("builtin:cornell (scene #") && text != scene.identity().to_string(), "{text}");
        assert_eq!(moved.identity().name(), "builtin:cornell");
    }
}
