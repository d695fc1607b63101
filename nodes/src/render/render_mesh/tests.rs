//! Tests of `render_mesh`.

use super::*;
use crate::btf::directions::DirectionSet;
use crate::mesh::primitive::{build, Params as MeshParams, Shape};
use crate::support::raytrace::camera::CameraParams;
use crate::support::raytrace::light::LightParams;
use crate::types::{Direction, DirectionPair, HeightField};
use mesoflow_testkit::node::OutputsExt;
use std::sync::Arc;

/// A BTF with the given views × lights over `n`×`n` texels, values from a hash.
pub(crate) fn test_btf(n: usize, views: &[[f64; 2]], lights: &[[f64; 2]]) -> Btf {
    let pairs: Vec<DirectionPair> = views
        .iter()
        .flat_map(|v| {
            lights.iter().map(|l| DirectionPair {
                view: Direction::degrees(v[0], v[1]),
                light: Direction::degrees(l[0], l[1]),
            })
        })
        .collect();
    let data = (0..pairs.len() * 3 * n * n)
        .map(|i| crate::support::rng::unit(crate::support::rng::hash(7, &[i as u64])) as f32)
        .collect();
    Btf {
        width: n,
        height: n,
        pairs,
        data,
    }
}

fn render(
    mesh: Mesh,
    btf: Arc<dyn mesoflow_runtime::Value>,
    mdf: Option<Mdf>,
    p: &Params,
) -> Result<(Image, f64), NodeError> {
    let ctx = NodeContext::detached(None);
    let mut inputs = Inputs::new().with("mesh", Arc::new(mesh)).with("btf", btf);
    if let Some(m) = mdf {
        inputs = inputs.with("mdf", Arc::new(m));
    }
    // As the engine does: the parameter checks (`prepare`), then the run.
    RenderMesh.check(p)?;
    let out = mesoflow_testkit::node::run_in(&ctx, &RenderMesh, p, &inputs)?;
    let img = out.value::<Image>("image").clone();
    let cov = out.get("coverage").unwrap().as_scalar().unwrap();
    Ok((img, cov))
}

fn plane_params(n: u32) -> Params {
    Params {
        camera: CameraParams {
            eye: [0.0, 0.0, 5.0],
            target: [0.0, 0.0, 0.0],
            orthographic: Some(1.0),
            resolution: [n, n],
            ..Default::default()
        },
        light: LightParams {
            direction: [1.0, 0.0, 1.0],
            position: None,
            intensity: 1.0,
            ..Default::default()
        },
        tiling: [1.0, 1.0],
        ..Default::default()
    }
}

fn plane() -> Mesh {
    build(&MeshParams {
        shape: Shape::Plane,
        size: 2.0,
        segments: [1, 1],
        ..Default::default()
    })
    .unwrap()
}

#[test]
fn a_plane_seen_head_on_reproduces_the_btf_view_texel_for_texel() {
    // Orthographic, 1 pixel per texel, pixel centres on texel centres: the local view is
    // exactly (θ = 0) and the light exactly (45°, 0°), so the pixel is that pair's texel.
    let btf = test_btf(8, &[[0.0, 0.0], [30.0, 0.0]], &[[45.0, 0.0], [45.0, 90.0]]);
    let (img, cov) = render(plane(), Arc::new(btf.clone()), None, &plane_params(8)).unwrap();
    assert_eq!(cov, 1.0);
    let pair = btf
        .pairs
        .iter()
        .position(|p| p.view.theta == 0.0 && p.light.phi == 0.0)
        .unwrap();
    let plane = btf.pair_image(pair);
    for y in 0..8 {
        for x in 0..8 {
            for c in 0..3 {
                let want = plane[c * 64 + y * 8 + x];
                let got = img.data[(y * 8 + x) * 3 + c];
                // f32 storage, f64 arithmetic: only the bilinear weights' rounding (~1e-16).
                assert!(
                    (got - want).abs() < 1e-6,
                    "({x}, {y}, {c}): {got} vs {want}"
                );
            }
        }
    }
}

#[test]
fn a_full_rank_basis_renders_what_the_raw_btf_renders() {
    let btf = test_btf(
        8,
        &[[0.0, 0.0], [30.0, 0.0], [30.0, 180.0]],
        &[[45.0, 0.0], [20.0, 90.0]],
    );
    let ctx = NodeContext::detached(None);
    let p: crate::btf::pca::Params = serde_json::from_str(r#"{"rank": 18}"#).unwrap();
    let out = mesoflow_testkit::node::run_in(
        &ctx,
        &crate::btf::pca::Pca,
        &p,
        &Inputs::new().with("btf", Arc::new(btf.clone())),
    )
    .unwrap();
    let basis = out.get("basis").unwrap().clone();
    let mut params = plane_params(16);
    params.camera.orthographic = None;
    params.camera.eye = [0.4, 0.3, 2.0];
    let (raw, _) = render(plane(), Arc::new(btf), None, &params).unwrap();
    let (pca, _) = render(plane(), basis, None, &params).unwrap();
    // Full rank reconstructs the BTF to f32 rounding of the factors (~1e-6 of values ≤ 1).
    let max = raw
        .data
        .iter()
        .zip(&pca.data)
        .map(|(a, b)| (a - b).abs())
        .fold(0f32, f32::max);
    assert!(max < 1e-4, "max difference {max}");
}

/// MDF of a flat tile sunk `depth` texels below the reference plane, at many views.
fn sunken_mdf(depth: f64) -> Mdf {
    let hf = HeightField::from_fn(8, 8, |_, _| 0.0);
    let p = crate::mdf::tabulate::Params {
        views: DirectionSet::Rings {
            thetas: vec![
                0.0, 15.0, 30.0, 45.0, 60.0, 70.0, 75.0, 80.0, 85.0, 88.0, 89.5,
            ],
            phis: (0..8).map(|k| k as f64 * 45.0).collect(),
        },
        depth: Some(depth),
        ..Default::default()
    };
    let ctx = NodeContext::detached(None);
    let out = mesoflow_testkit::node::run_in(
        &ctx,
        &crate::mdf::tabulate::Tabulate,
        &p,
        &Inputs::new().with("height", Arc::new(hf)),
    )
    .unwrap();
    out.value::<Mdf>("mdf").clone()
}

fn sphere() -> Mesh {
    build(&MeshParams {
        shape: Shape::Sphere,
        size: 1.0,
        segments: [96, 48],
        ..Default::default()
    })
    .unwrap()
}

#[test]
fn a_sunken_mdf_shrinks_the_sphere_outline_by_the_shell_test_amount() {
    // Closed form for the shell test on a sphere of radius R with a flat mesostructure at
    // depth T (d = T/cos θ at both faces): a ray at distance ρ from the centre hits iff its
    // chord 2√(R²−ρ²) exceeds 2T·R/√(R²−ρ²), i.e. ρ² < R(R − T). Orthographic, so the
    // covered area shrinks from πR² to πR(R − T): a fraction T/R of the plain disc.
    let btf = test_btf(4, &[[0.0, 0.0]], &[[0.0, 0.0]]);
    let mut p = plane_params(160);
    p.camera.orthographic = Some(1.1);
    p.shell = 0.1;
    let (_, plain) = render(sphere(), Arc::new(btf.clone()), None, &p).unwrap();
    let (_, zero) = render(sphere(), Arc::new(btf.clone()), Some(sunken_mdf(0.0)), &p).unwrap();
    assert_eq!(plain, zero, "a zero-depth MDF changes nothing");
    let (_, deep) = render(sphere(), Arc::new(btf), Some(sunken_mdf(4.0)), &p).unwrap();
    let lost = (plain - deep) / plain;
    eprintln!("plain coverage {plain}, with the MDF {deep}: lost fraction {lost}");
    // The MDF blends views between sampled rings (d = T/cos θ is convex in θ, so a blend
    // overestimates it slightly near the outline) and the disc's edge is pixelated
    // (160 px across: ~2% of the ring's area): 15% of the 10% covers both.
    assert!(
        (lost - 0.1).abs() < 0.015,
        "lost fraction {lost}, expected 0.1"
    );
}

#[test]
fn an_open_planes_shell_has_sides_rays_leave_and_enter_by_on_cpu_and_gpu() {
    // Closed form: the 2 × 2 plane over a flat mesostructure at the shell's bottom (0.1 below
    // it), seen orthographically at 45° from +x. What shows is that bottom: a ray entering
    // the top at x reaches it at x − 0.1, so entries within 0.1 of the far edge leave
    // through the shell's far side and miss, and rays passing under the near edge enter
    // through its side and meet the bottom up to 0.1 beyond it. The outline is the plain
    // plane's moved by 0.1: 5% of its pixels lost at the far edge, 5% gained at the near
    // one. (Without side walls nothing was lost; with walls that only bounded rays from
    // the top, nothing was gained.)
    let btf = test_btf(8, &[[0.0, 0.0]], &[[0.0, 0.0]]);
    let p = Params {
        camera: CameraParams {
            eye: [3.0, 0.0, 3.0],
            target: [0.0, 0.0, 0.0],
            // Not 1.6: its rows' centres would run exactly along the walls at y = ±1,
            // where f32 and f64 decide a ray in the wall's plane differently.
            orthographic: Some(1.61),
            resolution: [200, 200],
            ..Default::default()
        },
        shell: 0.1,
        ..plane_params(200)
    };
    let mdf = sunken_mdf(4.0);
    let material = Material::new(Source::Raw(&btf));
    let mesh = plane();
    let scene = |with_mdf: bool| Scene {
        mesh: &mesh,
        material: &material,
        mdf: with_mdf.then(|| MdfLookup::new(&mdf)),
        light: Light::new(&p.light).unwrap(),
        tiling: p.tiling,
        shell: p.shell,
        background: p.background,
        parallax: false,
        sides: shell_sides(&mesh, p.shell),
        aspect: Vec::new(),
        env: None,
        footprint: None,
    };
    let cam = Camera::new(&p.camera).unwrap();
    let plain = render_cpu(&scene(false), &cam, &p, &Counter::none())
        .unwrap()
        .1;
    let deep = render_cpu(&scene(true), &cam, &p, &Counter::none())
        .unwrap()
        .1;
    let count = |f: &dyn Fn(usize) -> bool| (0..plain.len()).filter(|&i| f(i)).count() as f64;
    let area = count(&|i| plain[i] > 0.5);
    let lost = count(&|i| plain[i] > 0.5 && deep[i] <= 0.5) / area;
    let gained = count(&|i| plain[i] <= 0.5 && deep[i] > 0.5) / area;
    // The plane's edges are pixelated (about 141 pixels across at 45°: 0.7% of its width).
    assert!(
        (lost - 0.05).abs() < 0.01 && (gained - 0.05).abs() < 0.01,
        "lost {lost}, gained {gained}, expected 0.05 each"
    );
    // The GPU path carves and extends the same outline. Only a missing capability may skip a
    // backend, with its message; any other error fails, and under MESOFLOW_REQUIRE_GPU=1 at
    // least one adapter must have rendered it.
    let mut tested = 0;
    for backends in [wgpu::Backends::PRIMARY, wgpu::Backends::GL] {
        let Ok(gpu) = mesoflow_runtime::Gpu::with_backends(backends) else {
            continue;
        };
        let ctx = NodeContext::detached(None);
        match render_gpu(&ctx, &gpu, &scene(true), &cam, &p) {
            Ok((_, m, _, _)) => {
                let differ = count(&|i| (m[i] > 0.5) != (deep[i] > 0.5)) / area;

                assert!(
                    differ < 0.002,
                    "{}: {differ} of the pixels differ",
                    gpu.describe()
                );
                tested += 1;
            }
            Err(e) if e.to_string().contains("cannot render") => {
                mesoflow_testkit::skip(&format!("{}: {e}", gpu.describe()));
            }
            Err(e) => panic!("{}: {e}", gpu.describe()),
        }
    }
    crate::support::gpu::require_tested(tested);
}

/// One orthographic pixel looking at the origin from 45° above +x.
fn one_ray_at_45_degrees() -> Camera {
    Camera::new(&CameraParams {
        eye: [3.0, 0.0, 3.0],
        target: [0.0, 0.0, 0.0],
        orthographic: Some(0.01),
        resolution: [1, 1],
        ..Default::default()
    })
    .unwrap()
}

#[test]
fn parallax_moves_the_lookup_by_the_mdf_offset() {
    // A 45° orthographic view (φ = 0) of the plane's centre over a flat MDF sunk 4 texels:
    // d = 4/cos 45° along the ray, i.e. 4 texels towards −u; on an 8-texel tile that is
    // Δu = −0.5. Without `parallax` the lookup stays at the entry texel.
    let mdf = sunken_mdf(4.0);
    let btf = test_btf(8, &[[0.0, 0.0]], &[[0.0, 0.0]]);
    let material = Material::new(Source::Raw(&btf));
    let mesh = plane();
    let cam = one_ray_at_45_degrees();
    let layers = crate::support::raytrace::layers::trace(&mesh, &cam, 1, &Counter::none());
    for (parallax, want_u) in [(false, 0.5), (true, 0.0)] {
        let scene = Scene {
            mesh: &mesh,
            material: &material,
            mdf: Some(MdfLookup::new(&mdf)),
            light: Light::new(&LightParams::default()).unwrap(),
            tiling: [1.0, 1.0],
            shell: 0.1,
            background: [0.0; 3],
            parallax,
            sides: Vec::new(),
            aspect: Vec::new(),
            env: None,
            footprint: None,
        };
        let (o, d) = cam.ray(0, 0);
        let (_, _, s, wo) = scene.hit(&layers, 0, o, d).unwrap();
        assert!((wo[0] - 0.5f64.sqrt()).abs() < 1e-9 && wo[1].abs() < 1e-9);
        assert!(
            (s.uv[0] - want_u).abs() < 1e-6 && (s.uv[1] - 0.5).abs() < 1e-6,
            "{:?}",
            s.uv
        );
    }
}

#[test]
fn a_stretched_tile_is_looked_up_in_its_own_proportions() {
    // A 4 × 1 quad carrying one 8-texel tile (tiling 1) under a 0.5 shell over a flat
    // floor 4 texels deep: one texel of depth is 1/8 world unit, one texel across is 1/2
    // along u and 1/8 along v, so k = (1/4, 1). Seen at 45° along u, the ray meets the
    // floor 0.5 below the top, 0.5 world units (1/8 of the quad) further along u; with the
    // tile's own proportions ignored the parallax would move the lookup a full tile
    // width × 0.5 = 4× too far.
    let mdf = sunken_mdf(4.0);
    let btf = test_btf(8, &[[0.0, 0.0]], &[[0.0, 0.0]]);
    let material = Material::new(Source::Raw(&btf));
    let mut mesh = Mesh {
        positions: vec![
            [-2., -0.5, 0.],
            [2., -0.5, 0.],
            [2., 0.5, 0.],
            [-2., 0.5, 0.],
        ],
        uvs: vec![[0., 0.], [1., 0.], [1., 1.], [0., 1.]],
        indices: vec![0, 1, 2, 0, 2, 3],
        ..Default::default()
    };
    mesh.compute_normals();
    mesh.compute_tangents();
    let aspect = texel_aspect(&mesh, [1.0, 1.0], 0.5, Some(&mdf));
    for k in &aspect {
        assert!(
            (k[0] - 0.25).abs() < 1e-6 && (k[1] - 1.0).abs() < 1e-6,
            "{k:?}"
        );
    }
    let cam = one_ray_at_45_degrees();
    let layers = crate::support::raytrace::layers::trace(&mesh, &cam, 1, &Counter::none());
    let scene = Scene {
        mesh: &mesh,
        material: &material,
        mdf: Some(MdfLookup::new(&mdf)),
        light: Light::new(&LightParams::default()).unwrap(),
        tiling: [1.0, 1.0],
        shell: 0.5,
        background: [0.0; 3],
        parallax: true,
        sides: Vec::new(),
        aspect,
        env: None,
        footprint: None,
    };
    let (o, d) = cam.ray(0, 0);
    let (t, t_front, s, _) = scene.hit(&layers, 0, o, d).unwrap();
    // 0.5 below the top at 45°: 0.5·√2 along the ray. The tile sees the ray at 14° from
    // its normal, between the MDF's rings at 0° and 15°, whose blend of 4/cos θ (convex)
    // is 0.2% long there: 0.5% bounds it.
    assert!(
        (t - t_front - 0.5 * 2f64.sqrt()).abs() < 4e-3,
        "{}",
        t - t_front
    );
    assert!((s.uv[0] - (0.5 - 0.125)).abs() < 1e-3, "{:?}", s.uv);
}

#[test]
fn missing_hits_grazing_views_and_few_directions_stay_finite() {
    let btf = test_btf(4, &[[0.0, 0.0]], &[[30.0, 0.0]]);
    let mut mdf = sunken_mdf(2.0);
    mdf.data
        .iter_mut()
        .step_by(3)
        .for_each(|d| *d = f32::INFINITY);
    let mut p = plane_params(32);
    p.camera.orthographic = None;
    p.camera.eye = [0.0, -3.0, 0.05]; // θ ≈ 89° over the plane
    p.camera.target = [0.0, 0.0, 0.0];
    p.camera.up = [0.0, 0.0, 1.0];
    let (img, _) = render(plane(), Arc::new(btf.clone()), Some(mdf.clone()), &p).unwrap();
    assert!(img.data.iter().all(|v| v.is_finite()));
    // An MDF that never hits shows only background.
    mdf.data.iter_mut().for_each(|d| *d = f32::INFINITY);
    let (img, cov) = render(
        sphere(),
        Arc::new(btf.clone()),
        Some(mdf),
        &plane_params(16),
    )
    .unwrap();
    assert_eq!(cov, 0.0);
    assert!(img.data.iter().all(|v| *v == 0.0));
    // 1×1 works; a huge image is refused, naming the camera.
    let mut p = plane_params(1);
    let (img, _) = render(plane(), Arc::new(btf.clone()), None, &p).unwrap();
    assert_eq!(img.data.len(), 3);
    p.camera.resolution = [100_000, 10];
    let e = render(plane(), Arc::new(btf), None, &p)
        .unwrap_err()
        .to_string();
    assert!(e.contains("camera") && e.contains("100000"), "{e}");
}

#[test]
fn degenerate_triangles_are_skipped_without_nan() {
    let btf = test_btf(4, &[[0.0, 0.0]], &[[30.0, 0.0]]);
    let mut m = plane();
    let n = m.positions.len() as u32;
    m.positions.push([0.0, 0.0, 0.5]);
    m.normals.push([0.0, 0.0, 1.0]);
    m.uvs.push([0.5, 0.5]);
    m.tangents.push([1.0, 0.0, 0.0, 1.0]);
    m.indices.extend_from_slice(&[n, n, n, 0, 0, 1]);
    let (img, cov) = render(m, Arc::new(btf), None, &plane_params(8)).unwrap();
    assert_eq!(cov, 1.0);
    assert!(img.data.iter().all(|v| v.is_finite()));
}

/// A woven tile's BTF (few directions) and MDF, as the graphs build them.
fn woven(size: u32) -> (Btf, Mdf) {
    let ctx = NodeContext::detached(None);
    let hp = crate::heightfield::procedural::Params {
        pattern: crate::heightfield::procedural::Pattern::Weave,
        size,
        count: 2,
        ..Default::default()
    };
    let hf: mesoflow_runtime::ValueRef =
        Arc::new(crate::heightfield::procedural::generate(&ctx, &hp).unwrap());
    let dirs = r#"{"thetas": [0, 30, 60, 80], "phis": [0, 60, 120, 180, 240, 300]}"#;
    let cp: crate::btf::capture::Params =
        serde_json::from_str(&format!(r#"{{"views": {dirs}, "lights": {dirs}}}"#)).unwrap();
    let btf = mesoflow_testkit::node::run_in(
        &ctx,
        &crate::btf::capture::Capture,
        &cp,
        &Inputs::new().with("height", hf.clone()),
    )
    .unwrap()
    .value::<Btf>("btf")
    .clone();
    let mp: crate::mdf::tabulate::Params =
        serde_json::from_str(&format!(r#"{{"views": {dirs}}}"#)).unwrap();
    let mdf = mesoflow_testkit::node::run_in(
        &ctx,
        &crate::mdf::tabulate::Tabulate,
        &mp,
        &Inputs::new().with("height", hf),
    )
    .unwrap()
    .value::<Mdf>("mdf")
    .clone();
    (btf, mdf)
}

/// A torus under a low light (the ring shadows its own inner side) with a thick shell (the
/// MDF's silhouettes cover enough pixels to matter), seen at 96 × 72 with a 256² shadow map.
fn shadowed_torus() -> (Mesh, Params) {
    let torus = build(&MeshParams {
        shape: Shape::Torus,
        size: 0.9,
        minor: 0.35,
        segments: [48, 24],
    })
    .unwrap();
    let p = Params {
        camera: CameraParams {
            eye: [0.0, 1.6, 2.4],
            resolution: [96, 72],
            ..Default::default()
        },
        light: LightParams {
            direction: [1.0, 0.45, 0.2],
            ..Default::default()
        },
        shell: 0.25,
        shadows: true,
        shadow_resolution: 256,
        ..Default::default()
    };
    (torus, p)
}

/// The scene `render_cpu` and `render_gpu` draw for `p`, with or without the MDF (the torus's
/// tiles are squeezed inside and stretched outside: the GPU must map directions into the tile's
/// proportions as the CPU does).
fn scene_of<'a>(
    mesh: &'a Mesh,
    material: &'a Material<'a>,
    mdf: Option<&'a Mdf>,
    p: &Params,
) -> Scene<'a> {
    scene_for(
        mesh,
        material,
        mdf.map(MdfLookup::new),
        p,
        Light::open(&p.light, &NodeContext::detached(None)).unwrap(),
    )
    .unwrap()
}

#[test]
fn gpu_and_cpu_renders_agree_on_every_backend() {
    let (btf, mdf) = woven(16);
    let (torus, mut p) = shadowed_torus();
    let scene_in = |gpu: Option<&mesoflow_runtime::Gpu>, with_mdf: bool, p: &Params| {
        let material = Material::new(Source::Raw(&btf));
        let mut scene = scene_of(&torus, &material, with_mdf.then_some(&mdf), p);
        if let Some(env) = scene.light.env() {
            let tracer = crate::support::raytrace::tracer::Tracer::new(&torus);
            let order = p.environment_order as usize;
            let shading = EnvShading::new(&material, &torus, &tracer, env, order).unwrap();
            scene.env = Some(shading);
        }
        let cam = Camera::new(&p.camera).unwrap();
        let ctx = NodeContext::detached(None);
        match gpu {
            Some(g) => render_gpu(&ctx, g, &scene, &cam, p).map(|(d, m, _, t)| {
                // Each stage's GPU time is there, positive and within the frame's (the total
                // is defined as their sum, so only the parts can be wrong).
                let st = ctx.timings();
                if let Some(total) = t {
                    assert!(st.contains_key("layers_ms") && st.contains_key("shade_ms"));
                    // Under an environment the shadows are in the lighting: no map.
                    let mapped = p.shadows && !p.light.is_environment();
                    assert_eq!(st.contains_key("shadow_ms"), mapped);
                    for k in ["layers_ms", "shade_ms", "shadow_ms"] {
                        if let Some(v) = st.get(k) {
                            assert!(
                                v.is_finite() && *v > 0.0 && *v <= total * (1.0 + 1e-9),
                                "{k}: {v} of {total}"
                            );
                        }
                    }
                }
                (d, coverage(&m), t)
            }),
            None => {
                render_cpu(&scene, &cam, p, &Counter::none()).map(|(d, m)| (d, coverage(&m), None))
            }
        }
    };
    // The MDF must matter in this scene, or agreement with it would prove nothing.
    let (plain, ..) = scene_in(None, false, &p).unwrap();
    let (meso, ..) = scene_in(None, true, &p).unwrap();
    let changed = plain
        .iter()
        .zip(&meso)
        .filter(|(a, b)| (*a - *b).abs() > 1e-3)
        .count();
    eprintln!(
        "the MDF changes {changed} of {} values (depth {}, mean {})",
        plain.len(),
        mdf.depth,
        mdf.data.iter().map(|v| *v as f64).sum::<f64>() / mdf.data.len() as f64
    );
    assert!(changed > plain.len() / 50);
    // Likewise the shadows: the near side of the ring shadows the inner wall across the hole
    // (a thin crescent at this resolution, 90 values when written).
    let mut lit = p.clone();
    lit.shadows = false;
    let (unshadowed, ..) = scene_in(None, true, &lit).unwrap();
    let darker = unshadowed
        .iter()
        .zip(&meso)
        .filter(|(a, b)| *a - *b > 1e-3)
        .count();
    eprintln!("shadows darken {darker} values");
    assert!(darker > plain.len() / 500);
    let mut tested = 0;
    for backends in [wgpu::Backends::PRIMARY, wgpu::Backends::GL] {
        let Ok(gpu) = mesoflow_runtime::Gpu::with_backends(backends) else {
            continue;
        };
        // The last two under the procedural sky: the environment's transfer and lighting,
        // with the MDF's depth read per view (the shadows are then in the lighting).
        let sun = p.light.clone();
        let sky: LightParams =
            serde_json::from_value(serde_json::json!({"sky": {}, "intensity": 2.0})).unwrap();
        for (with_mdf, shadows, parallax, environment) in [
            (false, false, false, false),
            (true, false, false, false),
            (true, true, false, false),
            (true, false, true, false),
            (false, false, false, true),
            (true, true, false, true),
        ] {
            p.shadows = shadows;
            p.parallax = parallax;
            p.light = if environment {
                sky.clone()
            } else {
                sun.clone()
            };
            let (cpu, cpu_cov, _) = scene_in(None, with_mdf, &p).unwrap();
            let (gpu_img, gpu_cov, gpu_ms) = match scene_in(Some(&gpu), with_mdf, &p) {
                Ok(r) => r,
                // Only a missing capability may skip a backend, and only with its message.
                Err(e) if e.to_string().contains("cannot render") => {
                    mesoflow_testkit::skip(&format!("{}: {e}", gpu.describe()));
                    break;
                }
                Err(e) => panic!("{e}"),
            };
            let peak = cpu.iter().fold(0f32, |a, b| a.max(*b));
            let pixels = cpu.len() / 3;
            let (mut sum, mut differing) = (0f64, 0);
            for (a, b) in cpu.chunks_exact(3).zip(gpu_img.chunks_exact(3)) {
                let d = (0..3).map(|k| (a[k] - b[k]).abs()).fold(0f32, f32::max);
                sum += d as f64;
                if d > 0.01 * peak {
                    differing += 1;
                }
            }
            let mean = sum / pixels as f64 / peak as f64;
            let frac = differing as f64 / pixels as f64;
            eprintln!(
                "{} mdf {with_mdf} shadows {shadows} parallax {parallax} sky {environment}: coverage CPU {cpu_cov:.4} GPU {gpu_cov:.4}, mean |diff| {mean:.2e} of peak, {frac:.4} of pixels differ by > 1%, GPU time {gpu_ms:?} ms",
                gpu.describe()
            );
            // Where they may differ: the rasteriser's edge rules vs the f64 ray–triangle test
            // at silhouettes and shared edges, f32 vs f64 at the shell test's threshold and the
            // shadow comparison. Those are isolated pixels along outlines: 0.5% of the pixels
            // and a mean difference of 5e-5 of the peak bound them (lavapipe measured 0
            // pixels and 5e-6; docs/guide/mdf.md quotes these bounds), while a wrong frame, lookup
            // or layer breaks whole regions and fails both.
            assert!(frac < 0.005, "{}: {frac} of pixels differ", gpu.describe());
            assert!(mean < 5e-5, "{}: mean difference {mean}", gpu.describe());
            assert!((cpu_cov - gpu_cov).abs() < 0.01);
            // Timestamps where the device has them, and a positive time.
            let stamps = gpu
                .device
                .features()
                .contains(wgpu::Features::TIMESTAMP_QUERY);
            assert_eq!(gpu_ms.is_some(), stamps);
            if environment {
                // Not the background: the sky lights the torus.
                assert!(peak > 0.05, "{peak}");
            }
            assert!(
                gpu_ms.is_none_or(|t| t > 0.0 && t.is_finite()),
                "{gpu_ms:?}"
            );
            tested += 1;
        }
        // Past the device's texture limit: a clear refusal naming the parameter.
        let mut huge = p.clone();
        huge.camera.resolution = [1 << 20, 8];
        let e = scene_in(Some(&gpu), false, &huge).unwrap_err().to_string();
        assert!(e.contains("camera") && e.contains("exceeds"), "{e}");
    }
    crate::support::gpu::require_tested(tested);
}

#[test]
fn the_lazy_shadow_map_holds_the_full_maps_depths_bit_for_bit_and_traces_only_what_a_frame_asks() {
    // The full map as render.mesh built it before (every texel's layers traced, then the
    // shell test through them) against the lazy map texel for texel: a texel's depth is a
    // function of the texel alone, so the same bits. And a frame traces far fewer texels than
    // the map has: at 96 × 72 pixels and a 512² map, at most one texel a pixel.
    let (btf, mdf) = woven(16);
    let (torus, mut p) = shadowed_torus();
    p.shadow_resolution = 512;
    let material = Material::new(Source::Raw(&btf));
    let scene = scene_of(&torus, &material, Some(&mdf), &p);
    let cam = shadow_camera(&scene, p.shadow_resolution).unwrap();
    let radius = bounding_sphere(&torus).1;
    let full_layers = layers::trace(&torus, &cam, 2, &Counter::none());
    let binned = layers::Binned::new(&torus, &cam);
    let lazy = scene.shadow_map(&binned, 2, radius);
    let n = (cam.width * cam.height) as usize;
    let mut surface = 0;
    for i in (0..n).step_by(7) {
        let (o, d) = cam.ray(i as u32 % cam.width, i as u32 / cam.width);
        let full = scene
            .hit(&full_layers, i, o, d)
            .map_or(f64::INFINITY, |h| h.0);
        assert_eq!(full.to_bits(), lazy.depth(i).to_bits(), "texel {i}");
        surface += full.is_finite() as usize;
    }
    assert!(surface > n / 7 / 10, "the light sees the torus: {surface}");

    let view = Camera::new(&p.camera).unwrap();
    let (_, _, stages) = render_cpu_stages(&scene, &view, &p, &Counter::none()).unwrap();
    let pixels = (view.width * view.height) as u64;
    eprintln!("{stages:?}");
    assert!(stages.shadow_texels > 0 && stages.shadow_texels <= pixels);
}

/// A plane tiled ever more finely by a tile of 16² random texels, seen head on at 16 × 16
/// pixels, against the same view supersampled 32 × 32 a pixel (each pixel the mean of 1 024
/// reads: the footprint's true mean, to about 2% where a pixel spans 46 texels a side). Read at
/// the footprint the error stays small as the tiles shrink from 5 pixels to a third of one;
/// read texel by texel it is the alias of one texel. Bounds set before the first run: relative
/// RMSE at most 0.08 at every tiling with the footprint (box levels against the footprint's
/// exact box, at the worst blend between levels), and at most half the texel reads' from a
/// footprint of 4 texels on. A single trilinear read at log₂ F measured 0.0825 at 3.3 texels a
/// pixel (its kernel three times the box's variance); the footprint read as four half-size
/// boxes measures 0.054, 0.031, 0.014 and 0.008 at 3.3, 7.7, 21 and 46 texels a pixel (0.043,
/// 0.030, 0.014 and 0.008 with each box fully trilinear).
#[test]
fn reading_at_the_footprint_keeps_the_error_flat_as_tiles_shrink() {
    let btf = Arc::new(test_btf(16, &[[0.0, 0.0]], &[[0.0, 0.0]]));
    let params = |tiles: f64, res: u32, footprint: bool| {
        let mut p = plane_params(res);
        p.tiling = [tiles, tiles];
        p.footprint = footprint;
        p
    };
    let rel = |a: &Image, b: &[f64]| {
        let (mut d2, mut r2) = (0.0, 0.0);
        for (x, y) in a.data.iter().zip(b) {
            d2 += (*x as f64 - y).powi(2);
            r2 += y * y;
        }
        (d2 / r2).sqrt()
    };
    let (n, ss) = (16usize, 32usize);
    for tiles in [3.3, 7.7, 21.3, 45.7] {
        let (fine, _) = render(
            plane(),
            btf.clone(),
            None,
            &params(tiles, (n * ss) as u32, false),
        )
        .unwrap();
        let mut truth = vec![0.0f64; n * n * 3];
        for y in 0..n * ss {
            for x in 0..n * ss {
                for c in 0..3 {
                    truth[((y / ss) * n + x / ss) * 3 + c] +=
                        fine.data[(y * n * ss + x) * 3 + c] as f64 / (ss * ss) as f64;
                }
            }
        }
        let (texel, _) =
            render(plane(), btf.clone(), None, &params(tiles, n as u32, false)).unwrap();
        let (level, _) =
            render(plane(), btf.clone(), None, &params(tiles, n as u32, true)).unwrap();
        let (e_texel, e_level) = (rel(&texel, &truth), rel(&level, &truth));
        eprintln!(
            "{:.1} texels a pixel: texel reads {e_texel:.4}, at the footprint {e_level:.4}",
            tiles * 16.0 / n as f64
        );
        assert!(e_level < 0.08, "{tiles}: {e_level}");
        if tiles * 16.0 / n as f64 >= 4.0 {
            assert!(e_level < 0.5 * e_texel, "{tiles}: {e_level} vs {e_texel}");
        }
    }
}
