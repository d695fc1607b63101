//! The planner's measured error model: the FLIP of each candidate model against the full model,
//! measured by `benches/plan_calibrate.rs` on its own calibration scene (not the verification
//! scene) over camera distances, as curves over what a view shows — texels per pixel for the
//! BTF, the shell's thickness in pixels for the MDF, the longest mean free path in pixels for
//! subsurface scattering — with the candidates' render times relative to the full model's.
//! Leaving the MDF out changes only a band along silhouettes and inner contours, as wide as the
//! shell projects (at least a pixel), so its error is kept per band pixel — FLIP over
//! [`band_fraction`] — and scaled by the view's own band: the calibration sphere has far fewer
//! contours than a torus seen from above.
//! A view between two calibrated distances is interpolated linearly in log₂ of the quantity;
//! beyond the calibrated range the nearest end stands in (and the reason says so).

use mesoflow_nodes::image::flip::DEFAULT_PPD;
use serde_json::Value;

/// The fraction of an object's pixels an MDF changes: its contour pixels, each widened to the
/// shell's projected thickness (at least one pixel).
pub fn band_fraction(silhouette_fraction: f64, shell_pixels: f64) -> f64 {
    (silhouette_fraction * shell_pixels.max(1.0)).clamp(1e-6, 1.0)
}

/// FLIP (and time ratio) against log₂ of what the view shows, sorted.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Curve {
    points: Vec<(f64, f64)>,
}

impl Curve {
    fn new(mut points: Vec<(f64, f64)>) -> Curve {
        points.retain(|(x, y)| x.is_finite() && y.is_finite());
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        Curve { points }
    }

    /// The same curve with every value times `k` (tests that need a model other than the
    /// measured one).
    #[cfg(test)]
    pub fn scaled(&self, k: f64) -> Curve {
        Curve::new(self.points.iter().map(|&(x, y)| (x, k * y)).collect())
    }

    /// The value at `x` (not its log), and whether `x` lies inside the calibrated range.
    pub fn at(&self, x: f64) -> Option<(f64, bool)> {
        let (first, last) = (self.points.first()?, self.points.last()?);
        let lx = x.max(1e-300).log2();
        if lx <= first.0 {
            return Some((first.1, lx == first.0));
        }
        if lx >= last.0 {
            return Some((last.1, lx == last.0));
        }
        let i = self.points.partition_point(|p| p.0 <= lx);
        let (a, b) = (self.points[i - 1], self.points[i]);
        let t = (lx - a.0) / (b.0 - a.0);
        Some((a.1 + t * (b.1 - a.1), true))
    }
}

/// Rows (key, FLIP point, time point) grouped by key in the order keys first appear, each
/// group's points made into its FLIP and time curves.
fn grouped<K: PartialEq>(
    rows: impl IntoIterator<Item = (K, (f64, f64), (f64, f64))>,
) -> Vec<(K, Curve, Curve)> {
    type Points = Vec<(f64, f64)>;
    let mut groups: Vec<(K, Points, Points)> = Vec::new();
    for (key, flip, time) in rows {
        match groups.iter_mut().find(|g| g.0 == key) {
            Some(g) => {
                g.1.push(flip);
                g.2.push(time);
            }
            None => groups.push((key, vec![flip], vec![time])),
        }
    }
    groups
        .into_iter()
        .map(|(k, flip, time)| (k, Curve::new(flip), Curve::new(time)))
        .collect()
}

#[derive(Clone, Debug, PartialEq)]
pub struct BtfOption {
    pub rank: u32,
    pub level: u32,
    pub flip: Curve,
    /// Render time over the raw BTF's.
    pub time: Curve,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SssOption {
    Brdf,
    /// Gathered with samples `footprints` pixel footprints apart (never closer than the
    /// profile's default spacing).
    Gather {
        footprints: f64,
    },
    /// Gathered as the full model is, from the classical dipole's profile instead of PBD's.
    Dipole,
    /// Gathered as the full model is on the CPU, by an octree at `threshold` (ΔA/d²) instead of
    /// brute force; times are the CPU's.
    Octree {
        threshold: f64,
    },
}

#[derive(Clone, Debug, PartialEq)]
pub struct SssCandidate {
    pub option: SssOption,
    /// The calibration medium the curves were measured on.
    pub medium: String,
    pub flip: Curve,
    /// Render time over the full model's.
    pub time: Curve,
}

/// A shadow map of `texels_per_pixel` texels per pixel the object spans
/// ([`mesoflow_nodes::support::raytrace::footprint::shadow_resolution`]), per renderer family.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Shadows {
    pub texels_per_pixel: f64,
    /// FLIP against the object's size in pixels.
    pub flip: Curve,
    /// Frame (or render) time over the full model's.
    pub time: Curve,
}

/// The MDF tabulated `factor` times coarser than its height field.
#[derive(Clone, Debug, PartialEq)]
pub struct MdfResolution {
    pub factor: u32,
    /// FLIP per unit of [`band_fraction`], against the full table's texels per pixel.
    pub flip_per_contour: Curve,
    /// Tabulation time over the full table's (the median of the measurements: it does not
    /// depend on the view).
    pub time: Option<f64>,
}

/// A synthesized texture stopped `stop_level` pyramid levels before its finest.
#[derive(Clone, Debug, PartialEq)]
pub struct SynthesisStop {
    pub stop_level: u32,
    /// FLIP of the render against the full texture's texels per pixel.
    pub flip: Curve,
    /// Synthesis time over the full synthesis's (the median of the measurements).
    pub time: Option<f64>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Calibration {
    /// `render.mesh` (and `qh.render`'s local term) and `sss.render`, by density, sparsest
    /// first.
    pub shadows_mesh: Vec<Shadows>,
    pub shadows_sss: Vec<Shadows>,
    pub btf: Vec<BtfOption>,
    /// FLIP of leaving the MDF out per unit of [`band_fraction`].
    pub mdf_off_per_contour: Curve,
    pub mdf_off_time: Curve,
    /// Coarser MDF tables, coarsest first.
    pub mdf_resolution: Vec<MdfResolution>,
    /// Synthesis stopped early, earliest (smallest output) first.
    pub synthesis: Vec<SynthesisStop>,
    pub sss: Vec<SssCandidate>,
    /// The classical dipole profile's computing time over PBD's, where measured.
    pub dipole_profile_time: Option<f64>,
    /// The viewing condition (pixels per degree) the FLIP curves were measured at: the
    /// calibrated one nearest at or below the viewer's, so that a viewer between two sees no
    /// more than predicted (FLIP falls as ppd rises).
    pub ppd: f64,
    /// Whether the viewer's ppd lies within the calibrated ones (below the sparsest, its curves
    /// stand in and may under-predict).
    pub ppd_inside: bool,
}

/// The table `benches/plan_calibrate.rs` wrote, compiled in.
const TABLE: &str = include_str!("../plan_calibration.json");

impl Calibration {
    /// The subsurface candidates, each with the worse prediction of the calibration media whose
    /// range holds `mfp_pixels` (error and time over the full model's): media that scatter
    /// differently disagree, and the plan must hold for the one it resembles least.
    pub fn sss_predictions(&self, mfp_pixels: f64) -> Vec<(SssOption, f64, f64)> {
        let mut out: Vec<(SssOption, f64, f64)> = Vec::new();
        for c in &self.sss {
            let (Some((e, true)), Some((t, _))) = (c.flip.at(mfp_pixels), c.time.at(mfp_pixels))
            else {
                continue;
            };
            match out.iter_mut().find(|o| o.0 == c.option) {
                Some(o) => {
                    o.1 = o.1.max(e);
                    o.2 = o.2.max(t);
                }
                None => out.push((c.option, e, t)),
            }
        }
        out
    }

    /// The compiled-in model, its FLIP read for a viewer at `ppd` pixels per degree.
    pub fn builtin(ppd: f64) -> Result<Calibration, String> {
        let doc: Value =
            serde_json::from_str(TABLE).map_err(|e| format!("calibration table: {e}"))?;
        Calibration::from_json(&doc, ppd)
    }

    /// Reads a table: the `flip` column is FLIP at its default [`DEFAULT_PPD`], `flip_at_ppd`
    /// holds the same at other pixels per degree.
    pub fn from_json(doc: &Value, ppd: f64) -> Result<Calibration, String> {
        let rows = |k: &str| -> Result<&Vec<Value>, String> {
            doc[k]
                .as_array()
                .ok_or_else(|| format!("calibration table: no `{k}`"))
        };
        let num = |v: &Value, k: &str| v[k].as_f64().unwrap_or(f64::NAN);
        // The calibrated viewing conditions, from the first row (every row has the same).
        let mut ppds: Vec<(f64, Option<String>)> = vec![(DEFAULT_PPD, None)];
        if let Some(m) = rows("btf")?
            .first()
            .and_then(|r| r["flip_at_ppd"].as_object())
        {
            for k in m.keys() {
                let p: f64 = k
                    .parse()
                    .map_err(|_| format!("calibration table: `{k}` is not a ppd"))?;
                ppds.push((p, Some(k.clone())));
            }
        }
        ppds.sort_by(|a, b| a.0.total_cmp(&b.0));
        // The densest calibrated ppd at or below the viewer's (67 asks for FLIP's 67.02): fewer
        // pixels per degree make each pixel's error larger in the eye, and the calibration
        // measured FLIP falling as ppd rises (by a median 1.4× for the BTF from 30 to 67).
        let (chosen, column, ppd_inside) = match ppds.iter().rev().find(|c| c.0 <= ppd + 0.05) {
            Some(c) => (c.0, c.1.clone(), true),
            None => ppds
                .first()
                .map(|c| (c.0, c.1.clone(), false))
                .ok_or("calibration table: no viewing condition")?,
        };
        let flip = |r: &Value| match &column {
            None => num(r, "flip"),
            Some(k) => r["flip_at_ppd"][k.as_str()].as_f64().unwrap_or(f64::NAN),
        };
        // Render time over the full model's: by frame where the renderer times one, else by
        // the node's seconds.
        let time = |r: &Value| match (r["frame_ms"].as_f64(), r["full_frame_ms"].as_f64()) {
            (Some(a), Some(b)) => a / b,
            _ => num(r, "seconds") / num(r, "full_seconds"),
        };
        let btf: Vec<BtfOption> = grouped(rows("btf")?.iter().map(|r| {
            let x = num(r, "texels_per_pixel").log2();
            (
                (num(r, "rank") as u32, num(r, "level") as u32),
                (x, flip(r)),
                (x, time(r)),
            )
        }))
        .into_iter()
        .map(|((rank, level), flip, time)| BtfOption {
            rank,
            level,
            flip,
            time,
        })
        .collect();
        let mdf = rows("mdf_off")?;
        let mdf_off_per_contour = Curve::new(
            mdf.iter()
                .map(|r| {
                    let shell = num(r, "shell_pixels");
                    let band = band_fraction(num(r, "silhouette_fraction"), shell);
                    (shell.log2(), flip(r) / band)
                })
                .collect(),
        );
        let mdf_off_time = Curve::new(
            mdf.iter()
                .map(|r| (num(r, "shell_pixels").log2(), time(r)))
                .collect(),
        );
        // A node's own time over the full model's: the median over the rows that measured it
        // (view-independent nodes are timed once and cached after).
        let median_ratio = |rows: &[&Value]| -> Option<f64> {
            let mut v: Vec<f64> = rows
                .iter()
                .map(|r| num(r, "seconds") / num(r, "full_seconds"))
                .filter(|v| v.is_finite() && *v > 0.0)
                .collect();
            v.sort_by(f64::total_cmp);
            v.get(v.len() / 2).copied()
        };
        let mdf_res_rows = rows("mdf_resolution")?;
        let mut mdf_resolution: Vec<MdfResolution> = grouped(mdf_res_rows.iter().map(|r| {
            let band = band_fraction(num(r, "silhouette_fraction"), num(r, "shell_pixels"));
            let x = num(r, "texels_per_pixel").log2();
            (num(r, "factor") as u32, (x, flip(r) / band), (x, 0.0))
        }))
        .into_iter()
        .map(|(factor, flip_per_contour, _)| MdfResolution {
            factor,
            flip_per_contour,
            time: median_ratio(
                &mdf_res_rows
                    .iter()
                    .filter(|r| num(r, "factor") as u32 == factor)
                    .collect::<Vec<_>>(),
            ),
        })
        .collect();
        mdf_resolution.sort_by_key(|m| std::cmp::Reverse(m.factor));
        let synth_rows = rows("synthesis")?;
        let mut synthesis: Vec<SynthesisStop> = grouped(synth_rows.iter().map(|r| {
            let x = num(r, "texels_per_pixel").log2();
            (num(r, "stop_level") as u32, (x, flip(r)), (x, 0.0))
        }))
        .into_iter()
        .map(|(stop_level, flip, _)| SynthesisStop {
            stop_level,
            flip,
            time: median_ratio(
                &synth_rows
                    .iter()
                    .filter(|r| num(r, "stop_level") as u32 == stop_level)
                    .collect::<Vec<_>>(),
            ),
        })
        .collect();
        synthesis.sort_by_key(|m| std::cmp::Reverse(m.stop_level));
        let sss: Vec<SssCandidate> = grouped(rows("sss")?.iter().map(|r| {
            let option = match r["option"].as_str() {
                Some("brdf") => SssOption::Brdf,
                Some("dipole") => SssOption::Dipole,
                Some("octree") => SssOption::Octree {
                    threshold: num(r, "threshold"),
                },
                _ => SssOption::Gather {
                    footprints: num(r, "spacing_footprints"),
                },
            };
            let medium = r["medium"].as_str().unwrap_or("").to_string();
            let x = num(r, "mfp_pixels").log2();
            ((option, medium), (x, flip(r)), (x, time(r)))
        }))
        .into_iter()
        .map(|((option, medium), flip, time)| SssCandidate {
            option,
            medium,
            flip,
            time,
        })
        .collect();
        // The dipole profile's own computing time over PBD's (the median of the measurements:
        // it does not depend on the view).
        let mut profile_ratios: Vec<f64> = rows("sss")?
            .iter()
            .filter(|r| r["option"] == "dipole")
            .map(|r| num(r, "profile_seconds") / num(r, "full_profile_seconds"))
            .filter(|v| v.is_finite())
            .collect();
        profile_ratios.sort_by(f64::total_cmp);
        let dipole_profile_time = profile_ratios.get(profile_ratios.len() / 2).copied();
        let shadows = |family: &str| -> Result<Vec<Shadows>, String> {
            let rows: Vec<&Value> = rows("shadows")?
                .iter()
                .filter(|r| r["renderer"] == family)
                .collect();
            let mut rows_by_density = Vec::new();
            for r in rows {
                let density = r["texels_per_pixel"].as_f64().ok_or_else(|| {
                    "calibration table: a shadow row without `texels_per_pixel`".to_string()
                })?;
                let x = num(r, "object_pixels").log2();
                rows_by_density.push((density, (x, flip(r)), (x, time(r))));
            }
            let mut out: Vec<Shadows> = grouped(rows_by_density)
                .into_iter()
                .map(|(texels_per_pixel, flip, time)| Shadows {
                    texels_per_pixel,
                    flip,
                    time,
                })
                .collect();
            out.sort_by(|a, b| a.texels_per_pixel.total_cmp(&b.texels_per_pixel));
            Ok(out)
        };
        let (shadows_mesh, shadows_sss) = (shadows("mesh")?, shadows("sss")?);
        if btf.is_empty() || sss.is_empty() {
            return Err("calibration table: no BTF or subsurface candidates".into());
        }
        Ok(Calibration {
            shadows_mesh,
            shadows_sss,
            btf,
            mdf_off_per_contour,
            mdf_off_time,
            mdf_resolution,
            synthesis,
            sss,
            dipole_profile_time,
            ppd: chosen,
            ppd_inside,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mesoflow_nodes::support::raytrace::footprint::SHADOW_TEXELS_PER_PIXEL;

    #[test]
    fn the_builtin_table_loads_and_covers_every_stage() {
        let c = Calibration::builtin(DEFAULT_PPD).unwrap();
        assert!(c.btf.len() >= 20);
        assert!(c.btf.iter().all(|o| o.flip.points.len() >= 6));
        assert!(c.mdf_off_per_contour.points.len() >= 6);
        assert_eq!(
            c.mdf_resolution
                .iter()
                .map(|m| m.factor)
                .collect::<Vec<_>>(),
            [8, 4, 2]
        );
        assert!(c
            .mdf_resolution
            .iter()
            .all(|m| m.flip_per_contour.points.len() >= 6
                && m.time.is_some_and(|t| t > 0.0 && t < 1.0)));
        assert_eq!(
            c.synthesis.iter().map(|m| m.stop_level).collect::<Vec<_>>(),
            [2, 1]
        );
        assert!(c
            .synthesis
            .iter()
            .all(|m| m.flip.points.len() >= 6 && m.time.is_some_and(|t| t > 0.0 && t < 1.0)));
        assert!(c.sss.iter().any(|s| s.option == SssOption::Brdf));
        assert!(c.sss.iter().any(|s| s.option == SssOption::Dipole));
        assert!(c
            .sss
            .iter()
            .any(|s| matches!(s.option, SssOption::Octree { .. })));
        assert!(c.dipole_profile_time.is_some_and(|t| t > 0.0 && t < 1.0));
        for family in [&c.shadows_mesh, &c.shadows_sss] {
            assert_eq!(family.len(), SHADOW_TEXELS_PER_PIXEL.len());
            assert!(family.iter().all(|s| s.flip.points.len() >= 6));
        }
        // Errors are FLIP values: in [0, 1].
        for o in &c.btf {
            assert!(o.flip.points.iter().all(|p| (0.0..=1.0).contains(&p.1)));
        }
    }

    #[test]
    fn curves_interpolate_in_log_and_hold_their_ends() {
        // Points at x = 1 and x = 4 (log₂ 0 and 2): x = 2 is halfway.
        let c = Curve::new(vec![(0.0, 0.1), (2.0, 0.3)]);
        assert!((c.at(2.0).unwrap().0 - 0.2).abs() < 1e-12);
        assert_eq!(c.at(0.5).unwrap(), (0.1, false));
        assert_eq!(c.at(100.0).unwrap(), (0.3, false));
        assert!(Curve::default().at(1.0).is_none());
    }
}
