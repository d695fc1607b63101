//! Direction sets for capture and sampling: the 81 directions of the Bonn UBO2003 database,
//! θ rings × φ steps, or an explicit list, as a parameter (`"ubo81"`, `{"thetas", "phis"}`,
//! `[[θ, φ], …]`, degrees).

use crate::types::Direction;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
#[serde(rename_all = "lowercase")]
pub enum Named {
    /// The UBO2003 sampling: θ = 0°, 15°, …, 75° with 1, 6, 12, 18, 20, 24 directions.
    Ubo81,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(untagged)]
pub enum DirectionSet {
    /// A named sampling.
    Named(Named),
    /// Every θ with every φ (θ = 0 gives one direction), degrees; θ in [0°, 90°).
    Rings {
        /// Polar angles from the normal, degrees, in [0°, 90°).
        #[schemars(length(min = 1), inner(range(min = 0.0, max = 89.999999)))]
        thetas: Vec<f64>,
        /// Azimuths from the tangent +x towards +y, degrees.
        #[schemars(length(min = 1))]
        phis: Vec<f64>,
    },
    /// Explicit [θ, φ] pairs, degrees; θ in [0°, 90°).
    List(#[schemars(schema_with = "list_schema")] Vec<[f64; 2]>),
}

/// At least one [θ, φ] pair, θ in [0°, 90°) (`prefixItems`: each position its own schema).
fn list_schema(_: &mut schemars::SchemaGenerator) -> schemars::Schema {
    schemars::json_schema!({
        "type": "array",
        "minItems": 1,
        "items": {
            "type": "array",
            "minItems": 2,
            "maxItems": 2,
            "prefixItems": [
                {"type": "number", "minimum": 0.0, "maximum": 89.999999},
                {"type": "number"}
            ]
        }
    })
}

impl DirectionSet {
    pub fn directions(&self) -> Vec<Direction> {
        match self {
            DirectionSet::Named(Named::Ubo81) => ubo81(),
            DirectionSet::Rings { thetas, phis } => thetas
                .iter()
                .flat_map(|&t| {
                    let phis: Vec<f64> = if t == 0.0 { vec![0.0] } else { phis.clone() };
                    phis.into_iter().map(move |p| Direction::degrees(t, p))
                })
                .collect(),
            DirectionSet::List(list) => list
                .iter()
                .map(|[t, p]| Direction::degrees(*t, *p))
                .collect(),
        }
    }

    /// Every θ must lie in [0°, 90°) (directions above the surface).
    pub fn validate(&self) -> Result<(), String> {
        let dirs = self.directions();
        if dirs.is_empty() {
            return Err("no directions".into());
        }
        match dirs
            .iter()
            .find(|d| !(0.0..std::f64::consts::FRAC_PI_2).contains(&d.theta) || !d.phi.is_finite())
        {
            Some(d) => Err(format!(
                "θ = {:.3}° is not in [0°, 90°): directions must point above the surface",
                d.theta.to_degrees()
            )),
            None => Ok(()),
        }
    }
}

/// The 81 UBO2003 directions, ring by ring, φ from 0° in every ring.
pub fn ubo81() -> Vec<Direction> {
    [
        (0.0, 360.0),
        (15.0, 60.0),
        (30.0, 30.0),
        (45.0, 20.0),
        (60.0, 18.0),
        (75.0, 15.0),
    ]
    .into_iter()
    .flat_map(|(theta, step): (f64, f64)| {
        let count = (360.0 / step).round() as usize;
        (0..count).map(move |k| Direction::degrees(theta, k as f64 * step))
    })
    .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ubo81_matches_the_published_table() {
        // domain notes §2: ring counts 1, 6, 12, 18, 20, 24 at θ = 0..75 step 15; 81 in all.
        let d = ubo81();
        assert_eq!(d.len(), 81);
        for (theta, count) in [
            (0.0, 1),
            (15.0, 6),
            (30.0, 12),
            (45.0, 18),
            (60.0, 20),
            (75.0, 24),
        ] {
            let ring = d
                .iter()
                .filter(|x| (x.theta.to_degrees() - theta).abs() < 1e-9)
                .count();
            assert_eq!(ring, count, "θ = {theta}");
        }
        assert!(d.iter().all(|x| x.phi.to_degrees() < 360.0 - 1e-9));
    }

    #[test]
    fn parameters_parse_in_all_three_forms() {
        let named: DirectionSet = serde_json::from_str(r#""ubo81""#).unwrap();
        assert_eq!(named.directions().len(), 81);
        let rings: DirectionSet =
            serde_json::from_str(r#"{"thetas": [0, 30], "phis": [0, 90, 180]}"#).unwrap();
        assert_eq!(rings.directions().len(), 4);
        let list: DirectionSet = serde_json::from_str("[[10, 20], [30, 40]]").unwrap();
        assert_eq!(list.directions()[1], Direction::degrees(30.0, 40.0));
        let below: DirectionSet = serde_json::from_str("[[95, 0]]").unwrap();
        assert!(below.validate().unwrap_err().contains("95"));
    }
}
