//! The Bonn UBO2014 formats against an independent writer and reader (`tests/peers/ubo2014.py`,
//! written from btflib's documentation with numpy's float16): every variant's factors read bit
//! for bit, the expanded BTF as the peer expands it, bad files refused with the file named, and
//! mesoflow's DFMF writer read back by the peer.

use crate::common::{mesoflow, peer_python, read_npy, Scratch};
use half::f16;
use mesoflow_nodes::btf::reconstruct::reconstruct;
use mesoflow_nodes::btf::ubo2014::{self, Payload};
use mesoflow_nodes::types::{BasisBlock, BtfBasis, Centring, ColorSpace, Direction, DirectionPair};
use std::path::{Path, PathBuf};
use std::process::Command;

const PEER: &str = "tests/peers/ubo2014.py";

fn peer(py: &Path, args: &[&str]) {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let o = Command::new(py)
        .arg(root.join(PEER))
        .args(args)
        .output()
        .expect("run the peer");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

fn same_bits(name: &str, ours: &[f32], theirs: &[f32]) {
    assert_eq!(ours.len(), theirs.len(), "{name}: length");
    for (i, (a, b)) in ours.iter().zip(theirs).enumerate() {
        assert_eq!(a.to_bits(), b.to_bits(), "{name}[{i}]: {a} vs {b}");
    }
}

/// Writes `graph` as NAME.json in the scratch folder and runs it uncached into out_NAME/ (the
/// files it reads are relative to the scratch folder): the run and its output folder.
fn run_graph(s: &Scratch, name: &str, graph: &str) -> (crate::common::Run, PathBuf) {
    let g = s.write(&format!("{name}.json"), graph);
    let out = s.path(&format!("out_{name}"));
    let args = [
        "run".to_string(),
        g.display().to_string(),
        "--quiet".into(),
        "--no-cache".into(),
        "--out-dir".into(),
        out.display().to_string(),
    ];
    let r = mesoflow(
        &args.iter().map(String::as_str).collect::<Vec<_>>(),
        s.dir.path(),
    );
    (r, out)
}

/// |ours − theirs| ≤ tol·(1 + |theirs|) everywhere.
fn close(name: &str, ours: &[f32], theirs: &[f32], tol: f32) {
    assert_eq!(ours.len(), theirs.len(), "{name}: length");
    let worst = ours
        .iter()
        .zip(theirs)
        .map(|(a, b)| (a - b).abs() / (1.0 + b.abs()))
        .fold(0f32, f32::max);
    assert!(worst <= tol, "{name}: worst relative difference {worst}");
}

#[test]
fn every_variant_reads_as_the_independent_writer_wrote_it() {
    let Some(py) = peer_python("numpy") else {
        return;
    };
    let s = Scratch::new();
    let dir = s.dir.path();
    let variants = [
        "dfmf_rgb",
        "dfmf_yuv_transposed",
        "dfmf_pca_f32",
        "fmf12_log_heightmap",
        "fmf06r_images",
        "fmf06",
        "pvf06r_lightfield",
        "pvf06_legacy_images",
    ];
    let mut signatures = std::collections::BTreeSet::new();
    for v in variants {
        peer(&py, &["write", v, &dir.display().to_string()]);
        let npy = |name: &str| read_npy(&dir.join(format!("{v}.{name}.npy"))).1;
        let bytes = std::fs::read(dir.join(format!("{v}.btf"))).unwrap();
        let file = ubo2014::parse(&bytes).unwrap_or_else(|e| panic!("{v}: {e}"));
        signatures.insert(file.header.signature.text());
        // The factors, bit for bit (half floats widened to f32 by numpy and by us).
        match &file.payload {
            Payload::Dfmf { channels, .. } => {
                for (c, ch) in channels.iter().enumerate() {
                    same_bits(&format!("{v} U{c}"), &ch.u, &npy(&format!("u{c}")));
                    same_bits(&format!("{v} S×V{c}"), &ch.sxv, &npy(&format!("sxv{c}")));
                }
            }
            Payload::Fmf { factor, .. } => {
                same_bits(&format!("{v} U"), &factor.u, &npy("u0"));
                same_bits(&format!("{v} S×V"), &factor.sxv, &npy("sxv0"));
            }
            Payload::Pvf { slots } => {
                for (i, slot) in slots.iter().enumerate() {
                    same_bits(&format!("{v} C{i}"), &slot.c, &npy(&format!("c{i}")));
                    same_bits(&format!("{v} W{i}"), &slot.w, &npy(&format!("w{i}")));
                    same_bits(&format!("{v} mean{i}"), &slot.mean, &npy(&format!("m{i}")));
                }
            }
        }
        // The expanded BTF through the command line. Tolerance: both sum the same stored
        // factors, the peer in f64, we in f64 from f32 products and round to f32: 1e-5.
        let graph = format!(
            r#"{{"mesoflow": 1, "nodes": {{
                "read": {{"kind": "btf.read_ubo2014", "params": {{"path": "{v}.btf"}}}},
                "npy": {{"kind": "npy.write", "inputs": {{"value": "read.btf"}}, "params": {{"path": "{v}.npy"}}}}
            }}}}"#
        );
        let (r, out) = run_graph(&s, v, &graph);
        assert_eq!(r.code, 0, "{v}: {}", r.stderr);
        let (shape, ours) = read_npy(&out.join(format!("{v}.npy")));
        let (want_shape, want) = read_npy(&dir.join(format!("{v}.expected.npy")));
        assert_eq!(shape, want_shape, "{v}");
        close(v, &ours, &want, 1e-5);
        // The linear variants also as a basis, not expanded: the same values once expanded.
        match ubo2014::nonlinear(&file) {
            None => close(
                &format!("{v} as a basis"),
                &reconstruct(&ubo2014::to_basis(&file, true)).data,
                &want,
                1e-5,
            ),
            Some(why) => assert!(
                matches!(
                    v,
                    "dfmf_pca_f32" | "fmf12_log_heightmap" | "pvf06_legacy_images"
                ),
                "{v}: {why}"
            ),
        }
    }
    assert_eq!(signatures.len(), 6, "{signatures:?}");
}

#[test]
fn bad_files_name_the_file_and_what_is_wrong() {
    let Some(py) = peer_python("numpy") else {
        return;
    };
    let s = Scratch::new();
    let dir = s.dir.path();
    peer(&py, &["write", "dfmf_rgb", &dir.display().to_string()]);
    let good = std::fs::read(dir.join("dfmf_rgb.btf")).unwrap();
    let truncated = &good[..good.len() - 7];
    let mut wrong_signature = good.clone();
    wrong_signature[1..5].copy_from_slice(b"XXXX");
    // The width (after the meta block and the directions) one larger: the factors no longer fit.
    let meta = u32::from_le_bytes(good[10..14].try_into().unwrap()) as usize;
    let width_at = 10 + meta + 4 + 2 * (8 + 4 + 3 * 8);
    let mut wrong_size = good.clone();
    wrong_size[width_at] += 1;
    // Issue 43: a width and height whose product with the channels wraps; a factor value that
    // is infinite (the last S×V value, a half float).
    let mut overflow = good.clone();
    overflow[width_at..width_at + 8].copy_from_slice(&[0xff; 8]);
    let mut infinite = good.clone();
    let n = infinite.len();
    infinite[n - 2..].copy_from_slice(&[0x00, 0x7c]);
    for (name, bytes, expect) in [
        ("overflow", overflow, "overflow"),
        (
            "infinite",
            infinite,
            "is not a finite single-precision number",
        ),
        (
            "truncated",
            truncated.to_vec(),
            "the file ends inside channel 2's S×V",
        ),
        ("signature", wrong_signature, "is none of UBO2014's"),
        (
            "size",
            wrong_size,
            "channel 0 is 6 × 20; the header asks for 6 × 24",
        ),
    ] {
        std::fs::write(dir.join(format!("{name}.btf")), &bytes).unwrap();
        let graph = format!(
            r#"{{"mesoflow": 1, "nodes": {{"read": {{"kind": "btf.read_ubo2014", "params": {{"path": "{name}.btf"}}}}}}}}"#
        );
        let (r, _) = run_graph(&s, name, &graph);
        assert_ne!(r.code, 0, "{name}");
        assert!(
            r.stderr.contains(&format!("{name}.btf")) && r.stderr.contains(expect),
            "{name}: {}",
            r.stderr
        );
    }
}

/// A basis with every kind of block mesoflow makes: a whole-RGB block centred per column over the
/// first view's pairs, and per-channel blocks centred per texel over the second view's.
fn basis(color: ColorSpace) -> BtfBasis {
    let (w, h) = (4, 3);
    let t = w * h;
    let views = [Direction::degrees(0.0, 0.0), Direction::degrees(30.0, 90.0)];
    let lights = [
        Direction::degrees(10.0, 0.0),
        Direction::degrees(45.0, 120.0),
        Direction::degrees(70.0, 240.0),
    ];
    let pairs: Vec<DirectionPair> = views
        .iter()
        .flat_map(|v| {
            lights.iter().map(move |l| DirectionPair {
                view: *v,
                light: *l,
            })
        })
        .collect();
    let wave = |i: usize, a: f32| (i as f32 * 0.37 + a).sin() * 0.4;
    let mut blocks = vec![BasisBlock {
        first_pair: 0,
        pair_count: 3,
        channel: None,
        centring: Centring::Columns,
        mean: (0..9).map(|j| 0.2 + 0.01 * j as f32).collect(),
        maps: (0..2 * t).map(|i| wave(i, 0.0)).collect(),
        basis: (0..2 * 9).map(|i| wave(i, 1.0)).collect(),
        singular: vec![3.0, 1.5],
    }];
    for c in 0..3u8 {
        blocks.push(BasisBlock {
            first_pair: 3,
            pair_count: 3,
            channel: Some(c),
            centring: Centring::Texels,
            mean: (0..t).map(|i| 0.1 + wave(i, c as f32).abs()).collect(),
            maps: (0..t).map(|i| wave(i, 2.0 + c as f32)).collect(),
            basis: (0..3).map(|i| wave(i, 3.0)).collect(),
            singular: vec![0.7],
        });
    }
    let b = BtfBasis {
        width: w,
        height: h,
        pairs,
        color,
        blocks,
    };
    b.check().unwrap();
    b
}

#[test]
fn our_dfmf_files_read_back_in_the_independent_reader() {
    let Some(py) = peer_python("numpy") else {
        return;
    };
    let s = Scratch::new();
    for (name, color) in [("rgb", ColorSpace::Rgb), ("ycbcr", ColorSpace::YCbCr)] {
        let b = basis(color);
        let bytes = ubo2014::write_dfmf(&b).unwrap();
        let path = s.path(&format!("{name}.btf"));
        std::fs::write(&path, &bytes).unwrap();
        let prefix = s.path(name);
        peer(
            &py,
            &[
                "read",
                &path.display().to_string(),
                &prefix.display().to_string(),
            ],
        );
        // Both readers see the same half floats.
        let Payload::Dfmf { channels, .. } = ubo2014::parse(&bytes).unwrap().payload else {
            panic!("not DFMF")
        };
        for (c, ch) in channels.iter().enumerate() {
            let npy = |f: &str| read_npy(Path::new(&format!("{}.{f}{c}.npy", prefix.display()))).1;
            same_bits(&format!("{name} U{c}"), &ch.u, &npy("u"));
            same_bits(&format!("{name} S×V{c}"), &ch.sxv, &npy("sxv"));
            assert!(
                ch.u.iter().all(|v| f16::from_f32(*v).to_f32() == *v),
                "U{c} holds halves"
            );
        }
        // The peer's expansion is the basis's reconstruction up to half rounding: each value
        // sums a handful of products of halves (relative error 2^-11 each) of magnitude < 1.
        let (_, theirs) = read_npy(Path::new(&format!("{}.expected.npy", prefix.display())));
        close(name, &reconstruct(&b).data, &theirs, 4e-3);
    }
}

#[test]
fn crop_stride_and_downsampling_act_on_the_factors_or_the_values_alike() {
    // A DFMF of our own (4×3 texels, 6 pairs) read three ways after a crop to the top 4×2 and a
    // 2× box: expanded (the box after expansion), as a basis (the box on the texel maps, then
    // btf.reconstruct) and by hand from the full expansion. The factors are linear, so all three
    // agree to f32 rounding (1e-6); a wrong window or box order would move whole texels.
    let s = Scratch::new();
    let dir = s.dir.path();
    let b = basis(ColorSpace::Rgb);
    std::fs::write(dir.join("ours.btf"), ubo2014::write_dfmf(&b).unwrap()).unwrap();
    let graph = r#"{"mesoflow": 1, "nodes": {
        "values": {"kind": "btf.read_ubo2014", "params": {"path": "ours.btf", "crop": [0, 0, 4, 2], "downsample": 2}},
        "factors": {"kind": "btf.read_ubo2014", "params": {"path": "ours.btf", "output": "basis", "crop": [0, 0, 4, 2], "downsample": 2}},
        "expanded": {"kind": "btf.reconstruct", "inputs": {"basis": "factors.basis"}},
        "full": {"kind": "btf.read_ubo2014", "params": {"path": "ours.btf"}},
        "strided": {"kind": "btf.read_ubo2014", "params": {"path": "ours.btf", "stride": 2}},
        "d": {"kind": "npy.write", "inputs": {"value": "strided.btf"}, "params": {"path": "strided.npy"}},
        "a": {"kind": "npy.write", "inputs": {"value": "values.btf"}, "params": {"path": "values.npy"}},
        "b": {"kind": "npy.write", "inputs": {"value": "expanded.btf"}, "params": {"path": "factors.npy"}},
        "c": {"kind": "npy.write", "inputs": {"value": "full.btf"}, "params": {"path": "full.npy"}}
    }}"#;
    let (r, out) = run_graph(&s, "down", graph);
    assert_eq!(r.code, 0, "{}", r.stderr);
    let (shape, values) = read_npy(&out.join("values.npy"));
    let (_, factors) = read_npy(&out.join("factors.npy"));
    let (full_shape, full) = read_npy(&out.join("full.npy"));
    assert_eq!(shape, vec![6, 3, 1, 2]);
    assert_eq!(full_shape, vec![6, 3, 3, 4]);
    let by_hand: Vec<f32> = (0..6 * 3)
        .flat_map(|plane| {
            let f = &full[plane * 12..(plane + 1) * 12];
            [0, 2].map(|x| (f[x] + f[x + 1] + f[4 + x] + f[4 + x + 1]) / 4.0)
        })
        .collect();
    close("expanded then boxed", &values, &by_hand, 1e-6);
    close("boxed factors", &factors, &by_hand, 1e-6);
    // Every second texel of the 4×3: columns 0 and 2 of rows 0 and 2, exactly.
    let (strided_shape, strided) = read_npy(&out.join("strided.npy"));
    assert_eq!(strided_shape, vec![6, 3, 2, 2]);
    let picked: Vec<f32> = (0..6 * 3)
        .flat_map(|plane| [0, 2, 8, 10].map(|i| full[plane * 12 + i]))
        .collect();
    same_bits("strided", &strided, &picked);
    // A size the factor does not divide is refused, naming the parameter.
    let bad = r#"{"mesoflow": 1, "nodes": {"r": {"kind": "btf.read_ubo2014", "params": {"path": "ours.btf", "downsample": 2}}}}"#;
    let (r, _) = run_graph(&s, "bad", bad);
    assert!(
        r.code != 0 && r.stderr.contains("downsample") && r.stderr.contains("4×3"),
        "{}",
        r.stderr
    );
}
