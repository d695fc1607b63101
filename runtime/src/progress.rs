//! Progress thinned to steps: a node's workers report counts from several threads, so they can
//! arrive out of order; an observer that forwards progress somewhere costly (the GIL, a socket)
//! passes each count through [`ProgressSteps`], which admits one count per step past the highest
//! admitted, so at most `steps + 1` counts a node reach it under any load.

use std::collections::HashMap;
use std::sync::Mutex;

pub struct ProgressSteps {
    steps: u64,
    highest: Mutex<HashMap<String, u64>>,
}

impl ProgressSteps {
    /// Steps of `1 / steps` of the total (20: steps of 5%).
    pub fn new(steps: u64) -> ProgressSteps {
        ProgressSteps {
            steps: steps.max(1),
            highest: Mutex::new(HashMap::new()),
        }
    }

    /// Whether node `id`'s count `done` of `total` starts a step not yet admitted for it.
    pub fn admit(&self, id: &str, done: u64, total: u64) -> bool {
        let step = (done.min(total).saturating_mul(self.steps) / total.max(1)).min(self.steps);
        let mut highest = self.highest.lock().unwrap_or_else(|e| e.into_inner());
        match highest.get_mut(id) {
            Some(h) if step <= *h => false,
            Some(h) => {
                *h = step;
                true
            }
            None => {
                highest.insert(id.to_string(), step);
                true
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_out_of_order_never_pass_more_than_one_per_step() {
        // 81 views reported by two workers whose counts interleave, each late by one: the
        // order 1, 0, 3, 2, … crosses every step boundary twice. The old throttle compared with
        // the last step only and let 23 through where 21 is the bound (issue 39).
        let p = ProgressSteps::new(20);
        let mut order: Vec<u64> = Vec::new();
        for pair in (0..=81u64).collect::<Vec<_>>().chunks(2) {
            order.extend(pair.iter().rev());
        }
        let admitted: Vec<u64> = order
            .iter()
            .copied()
            .filter(|&d| p.admit("cap", d, 81))
            .collect();
        assert!(admitted.len() <= 21, "{admitted:?}");
        assert!(admitted.windows(2).all(|w| w[0] < w[1]), "{admitted:?}");
        assert_eq!(admitted.last(), Some(&81));
        // Nodes are counted apart; a count past the total is the last step, not a 22nd.
        assert!(p.admit("other", 0, 81));
        assert!(!p.admit("cap", 500, 81));
    }
}
