//! The one light of a scene: directional (irradiance `intensity` on a plane facing it), a point
//! light (intensity with 1/r² falloff), or an environment around the scene (a lat-long image
//! file, a procedural sky or studio: `environment.rs`), as parameters and resolved, for
//! `render.mesh`, `render.reference`, `sss.render`, `qh.render`, the exports and the planner.
//! An environment is read once per content and shared ([`Light::open`]); a node that cannot
//! shade one refuses it by name ([`Light::new`]).

use super::environment::{Environment, SkyParams, StudioParams, PROCEDURAL_SIZE};
use crate::support::geometry::{dot, normalize, sub, V3};
use mesoflow_runtime::{NodeContext, NodeError};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct LightParams {
    /// Direction towards a directional light (world, need not be unit length).
    pub direction: [f64; 3],
    /// Position of a point light; when set the light is a point light with 1/r² falloff.
    pub position: Option<[f64; 3]>,
    /// Irradiance on a plane facing a directional light (or intensity of a point light); for an
    /// environment, the factor its radiance is multiplied by.
    #[schemars(range(min = 0.0))]
    pub intensity: f64,
    /// An environment around the scene instead: a linear lat-long HDR image (EXR, or `.npy` of
    /// shape (H, W, 3)), relative to the graph file; row 0 looks up (+z), columns run from +x
    /// towards +y. `direction` and `position` are then unused.
    pub environment: Option<String>,
    /// A procedural sky instead (no file): sky blue to the horizon, a soft sun, dim ground.
    pub sky: Option<SkyParams>,
    /// A procedural studio instead (no file): two soft windows in a dim room.
    pub studio: Option<StudioParams>,
    /// Rotation of an environment about +z, degrees.
    pub rotation: f64,
}

impl Default for LightParams {
    fn default() -> Self {
        LightParams {
            direction: [0.6, 0.7, 0.9],
            position: None,
            intensity: 3.0,
            environment: None,
            sky: None,
            studio: None,
            rotation: 0.0,
        }
    }
}

impl LightParams {
    /// Whether this is an environment (a file, a sky or a studio).
    pub fn is_environment(&self) -> bool {
        self.environment.is_some() || self.sky.is_some() || self.studio.is_some()
    }

    /// The file an environment light reads, for the node's `files` (its content is part of the
    /// cache key).
    pub fn files(&self, base: &Path) -> Vec<PathBuf> {
        self.environment.iter().map(|p| base.join(p)).collect()
    }
}

/// A checked light: unit direction, optional position, intensity, and the environment where
/// the light is one.
#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    /// Unit direction towards a directional light.
    pub direction: V3,
    /// Position of a point light (then `direction` only breaks ties at the light itself).
    pub position: Option<V3>,
    pub intensity: f64,
    /// The environment, intensity and rotation applied; `None` for a directional or point light.
    pub environment: Option<Arc<Environment>>,
}

impl Light {
    /// A directional or point light; an environment is refused by name (for the nodes that do
    /// not shade one). Errors name the parameter `light`.
    pub fn new(p: &LightParams) -> Result<Light, NodeError> {
        if p.is_environment() {
            return Err(NodeError::param(
                "light",
                "an environment light (environment, sky or studio) is not supported by this node: give a directional or point light",
            ));
        }
        Self::directional(p)
    }

    /// The parameters checked, an environment's included, without reading its file (for a
    /// node's `check`).
    pub fn check(p: &LightParams) -> Result<(), NodeError> {
        let kinds = [p.environment.is_some(), p.sky.is_some(), p.studio.is_some()];
        if kinds.iter().filter(|k| **k).count() > 1 {
            return Err(NodeError::param(
                "light",
                "give one of environment, sky and studio",
            ));
        }
        if p.is_environment() && p.position.is_some() {
            return Err(NodeError::param(
                "light",
                "an environment has no position: drop `position` or the environment",
            ));
        }
        if !p.rotation.is_finite() {
            return Err(NodeError::param("light", "rotation must be finite"));
        }
        if let Some(s) = &p.sky {
            s.texels().map_err(|e| NodeError::param("light", e))?;
        }
        if let Some(s) = &p.studio {
            s.texels().map_err(|e| NodeError::param("light", e))?;
        }
        Self::directional(p).map(drop)
    }

    /// Any light, an environment's file read (relative to the graph's folder) and shared
    /// between the nodes that use the same content, intensity and rotation.
    pub fn open(p: &LightParams, ctx: &NodeContext) -> Result<Light, NodeError> {
        Self::check(p)?;
        let mut light = Self::directional(p)?;
        if !p.is_environment() {
            return Ok(light);
        }
        let (w, h) = PROCEDURAL_SIZE;
        let make = |texels: Result<Vec<[f32; 3]>, String>, w: usize, h: usize| {
            texels
                .and_then(|t| Environment::new(w, h, &t, p.intensity, p.rotation.to_radians()))
                .map_err(|e| NodeError::param("light", e))
        };
        let env = if let Some(s) = &p.sky {
            shared(make(s.texels(), w, h)?)
        } else if let Some(s) = &p.studio {
            shared(make(s.texels(), w, h)?)
        } else {
            let file = p.environment.as_deref().unwrap_or_default();
            let path = ctx.input_path("light", file)?;
            let (tw, th, texels) = read_lat_long(&path)?;
            let env = Environment::new(tw, th, &texels, p.intensity, p.rotation.to_radians())
                .map_err(|e| NodeError::file(&path, e))?;
            shared(env)
        };
        if env.is_black() {
            ctx.warn("the environment light is black everywhere: the image will be too");
        }
        light.environment = Some(env);
        Ok(light)
    }

    /// The environment, where the light is one.
    pub fn env(&self) -> Option<&Environment> {
        self.environment.as_deref()
    }

    fn directional(p: &LightParams) -> Result<Light, NodeError> {
        let direction = normalize(p.direction)
            .ok_or_else(|| NodeError::param("light", "direction has zero length"))?;
        if !(p.intensity >= 0.0 && p.intensity.is_finite()) {
            return Err(NodeError::param(
                "light",
                "intensity must be finite and not negative",
            ));
        }
        if p.position.is_some_and(|q| q.iter().any(|v| !v.is_finite())) {
            return Err(NodeError::param("light", "position must be finite"));
        }
        Ok(Light {
            direction,
            position: p.position,
            intensity: p.intensity,
            environment: None,
        })
    }

    /// Unit direction towards the light and the irradiance on a surface facing it, at `x`.
    pub fn at(&self, x: V3) -> (V3, f64) {
        match self.position {
            None => (self.direction, self.intensity),
            Some(q) => {
                let d = sub(q, x);
                let r2 = dot(d, d).max(1e-30);
                (normalize(d).unwrap_or(self.direction), self.intensity / r2)
            }
        }
    }

    /// How far along `l` (the direction `at` gave at `x`) the light lies: the length a shadow
    /// ray must clear; infinite for a directional light.
    pub fn reach(&self, x: V3, l: V3) -> f64 {
        self.position.map_or(f64::INFINITY, |q| dot(sub(q, x), l))
    }
}

/// One copy per content: the renderers of a graph (and their frames) share an environment and
/// its sampling tables. Holds the last few.
fn shared(env: Environment) -> Arc<Environment> {
    static CACHE: OnceLock<Mutex<Vec<Arc<Environment>>>> = OnceLock::new();
    let mut cache = CACHE
        .get_or_init(|| Mutex::new(Vec::new()))
        .lock()
        .unwrap_or_else(|e| e.into_inner());
    if let Some(e) = cache.iter().find(|e| e.id == env.id) {
        return e.clone();
    }
    let env = Arc::new(env);
    if cache.len() >= 4 {
        cache.remove(0);
    }
    cache.push(env.clone());
    env
}

/// A lat-long image's texels: EXR (or any image `image.read` reads; 8-bit files are
/// sRGB-decoded) or `.npy` of shape (H, W, 3), float32 or float64.
fn read_lat_long(path: &Path) -> Result<(usize, usize, Vec<[f32; 3]>), NodeError> {
    let is_npy = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"));
    if is_npy {
        let a = crate::support::npy::read(path, 3, "(H, W, 3)")?;
        if a.shape[2] != 3 {
            return Err(NodeError::file(
                path,
                format!("expected (H, W, 3) linear RGB, got shape {:?}", a.shape),
            ));
        }
        let texels = a
            .data
            .chunks_exact(3)
            .map(|c| [c[0] as f32, c[1] as f32, c[2] as f32])
            .collect();
        return Ok((a.shape[1], a.shape[0], texels));
    }
    let img = crate::support::formats::read_image(path)?;
    let texels = img
        .data
        .chunks_exact(img.channels.max(1))
        .map(|c| match c.len() {
            1 | 2 => [c[0]; 3],
            _ => [c[0], c[1], c[2]],
        })
        .collect();
    Ok((img.width, img.height, texels))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_light_falls_off_as_inverse_square() {
        let l = Light::new(&LightParams {
            position: Some([0.0, 0.0, 2.0]),
            intensity: 8.0,
            ..Default::default()
        })
        .unwrap();
        let (d, e) = l.at([0.0; 3]);
        assert_eq!(d, [0.0, 0.0, 1.0]);
        assert!((e - 2.0).abs() < 1e-12);
    }

    /// A `.npy` lat-long file is read relative to the graph's folder, shared by content, and
    /// looked up as written (row 0 up); an EXR of the same texels is the same environment.
    #[test]
    fn an_environment_file_is_read_relative_to_the_graph() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (8usize, 4usize);
        let texels: Vec<f32> = (0..w * h * 3).map(|i| (i / 3) as f32 / 10.0).collect();
        let npy = crate::support::formats::encode_npy(&[h, w, 3], &texels).unwrap();
        std::fs::write(dir.path().join("env.npy"), npy).unwrap();
        let img = crate::types::Image {
            width: w,
            height: h,
            channels: 3,
            data: texels.clone(),
        };
        std::fs::write(
            dir.path().join("env.exr"),
            crate::support::formats::encode_exr(&img).unwrap(),
        )
        .unwrap();
        let ctx = NodeContext::detached(None).with_base(dir.path().to_path_buf());
        let open = |file: &str| {
            Light::open(
                &LightParams {
                    environment: Some(file.into()),
                    intensity: 2.0,
                    ..Default::default()
                },
                &ctx,
            )
            .unwrap()
        };
        let (a, b) = (open("env.npy"), open("env.exr"));
        assert_eq!(a, b);
        assert!(Arc::ptr_eq(
            a.environment.as_ref().unwrap(),
            b.environment.as_ref().unwrap()
        ));
        // Straight up is row 0; texel (0, 0) holds 0, so the first texel along +x just above
        // the horizon is row 1 (of 4), column 0: value 8/10, times the intensity.
        let env = a.env().unwrap();
        assert_eq!(env.radiance([0.0, 0.0, 1.0]), [0.0; 3]);
        let l = env.radiance([0.999, 0.01, 0.03]);
        assert!((l[0] - 1.6).abs() < 1e-6, "{l:?}");
        let missing = Light::open(
            &LightParams {
                environment: Some("none.exr".into()),
                ..Default::default()
            },
            &ctx,
        );
        assert!(missing.unwrap_err().to_string().contains("light"));
    }

    #[test]
    fn an_environment_is_refused_where_it_is_not_shaded_and_kinds_do_not_mix() {
        let sky = LightParams {
            sky: Some(SkyParams::default()),
            ..Default::default()
        };
        assert!(Light::check(&sky).is_ok());
        assert!(Light::new(&sky)
            .unwrap_err()
            .to_string()
            .contains("not supported"));
        let both = LightParams {
            studio: Some(StudioParams::default()),
            ..sky
        };
        assert!(Light::check(&both)
            .unwrap_err()
            .to_string()
            .contains("one of"));
    }

    #[test]
    fn bad_lights_name_the_parameter() {
        for p in [
            LightParams {
                direction: [0.0; 3],
                ..Default::default()
            },
            LightParams {
                intensity: -1.0,
                ..Default::default()
            },
            LightParams {
                intensity: f64::NAN,
                ..Default::default()
            },
        ] {
            assert!(Light::new(&p).unwrap_err().to_string().contains("light"));
        }
    }
}
