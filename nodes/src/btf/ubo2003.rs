//! The Bonn UBO2003 file naming: one image per direction pair, the four angles in integer
//! degrees in the name, `tlNNN?plNNN?tvNNN?pvNNN` (light θ, φ, view θ, φ; any one character
//! between the fields), optionally after a running index, e.g. `00042_tl015_pl060_tv000_pv000.png`.
//! Readers parse the angles from the name, never from positions in a listing.

use crate::types::{Direction, DirectionPair};

/// What a file name says.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Name {
    /// The leading run of digits, when the name starts with one.
    pub index: Option<u64>,
    /// [light θ, light φ, view θ, view φ], degrees.
    pub angles: [u16; 4],
}

impl Name {
    pub fn pair(&self) -> DirectionPair {
        let [tl, pl, tv, pv] = self.angles.map(f64::from);
        DirectionPair {
            view: Direction::degrees(tv, pv),
            light: Direction::degrees(tl, pl),
        }
    }

    /// View θ, view φ, light θ, light φ: the view-major order of a `Btf`.
    pub fn view_major(&self) -> [u16; 4] {
        let [tl, pl, tv, pv] = self.angles;
        [tv, pv, tl, pl]
    }
}

/// Parses a file name (without folders); `None` if it does not carry the four angles.
pub fn parse(file_name: &str) -> Option<Name> {
    let b = file_name.as_bytes();
    let digits = |at: usize| -> Option<u16> {
        let s = b.get(at..at + 3)?;
        s.iter()
            .all(u8::is_ascii_digit)
            .then(|| s.iter().fold(0u16, |v, d| v * 10 + (d - b'0') as u16))
    };
    let field = |at: usize, tag: &[u8]| -> Option<u16> {
        (b.get(at..at + 2)? == tag).then_some(())?;
        digits(at + 2)
    };
    (0..b.len()).find_map(|i| {
        let angles = [
            field(i, b"tl")?,
            field(i + 6, b"pl")?,
            field(i + 12, b"tv")?,
            field(i + 18, b"pv")?,
        ];
        let lead = b.iter().take_while(|c| c.is_ascii_digit()).count();
        let index = (lead > 0 && lead < 20)
            .then(|| file_name[..lead].parse().ok())
            .flatten();
        Some(Name { index, angles })
    })
}

/// Integer degrees of an angle in radians, if it is one (to 1e-6°).
fn whole_degrees(radians: f64, max: f64) -> Option<u16> {
    let d = radians.to_degrees();
    let r = d.round();
    ((d - r).abs() < 1e-6 && (0.0..max).contains(&r)).then_some(r as u16)
}

/// `{index:05}_tlNNN_plNNN_tvNNN_pvNNN.{ext}`, or why the pair has no such name.
pub fn file_name(index: usize, pair: &DirectionPair, ext: &str) -> Result<String, String> {
    let angle = |d: &Direction, what: &str| -> Result<(u16, u16), String> {
        let phi = d.phi.to_degrees().rem_euclid(360.0).to_radians();
        match (whole_degrees(d.theta, 90.0), whole_degrees(phi, 360.0)) {
            (Some(t), Some(p)) => Ok((t, p)),
            _ => Err(format!(
                "{what} direction (θ {:.4}°, φ {:.4}°) is not in whole degrees, which UBO2003 names require",
                d.theta.to_degrees(),
                d.phi.to_degrees()
            )),
        }
    };
    let (tl, pl) = angle(&pair.light, "light")?;
    let (tv, pv) = angle(&pair.view, "view")?;
    Ok(format!(
        "{index:05}_tl{tl:03}_pl{pl:03}_tv{tv:03}_pv{pv:03}.{ext}"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_in_the_published_forms() {
        let n = parse("00042 tl015 pl060 tv000 pv000.jpg").unwrap();
        assert_eq!(n.index, Some(42));
        assert_eq!(n.angles, [15, 60, 0, 0]);
        let n = parse("tl075_pl345_tv060_pv018.exr").unwrap();
        assert_eq!((n.index, n.angles), (None, [75, 345, 60, 18]));
        assert!(parse("tl15_pl60_tv0_pv0.png").is_none());
        assert!(parse("notes.txt").is_none());
        let pair = DirectionPair {
            view: Direction::degrees(60.0, 18.0),
            light: Direction::degrees(75.0, 345.0),
        };
        let name = file_name(7, &pair, "png").unwrap();
        assert_eq!(name, "00007_tl075_pl345_tv060_pv018.png");
        assert_eq!(parse(&name).unwrap().pair(), pair);
        let odd = DirectionPair {
            view: Direction::degrees(12.5, 0.0),
            ..pair
        };
        assert!(file_name(0, &odd, "png")
            .unwrap_err()
            .contains("whole degrees"));
    }
}
