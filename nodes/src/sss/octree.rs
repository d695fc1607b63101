//! The hierarchical evaluation of Jensen & Buhler 2002: irradiance sample points in an octree
//! whose nodes carry the sum of E·ΔA per channel and their E·ΔA-weighted mean position. A node far
//! enough from the shaded point — outside its box and seen under a solid angle ΔA/d² below the
//! threshold — is evaluated as one point source; nearer nodes are opened down to single points.
//! Threshold 0 opens everything (brute force).

/// One irradiance sample: position (mm), unit surface normal and E·ΔA per channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Source {
    pub p: [f64; 3],
    pub n: [f64; 3],
    pub power: [f64; 3],
}

struct Node {
    lo: [f64; 3],
    hi: [f64; 3],
    /// Weighted mean position and normal (unit, or zero where the normals cancel), summed power.
    centre: [f64; 3],
    normal: [f64; 3],
    power: [f64; 3],
    area: f64,
    /// Children (indices into `nodes`), or for a leaf the range of `order`.
    children: Vec<usize>,
    first: usize,
    count: usize,
}

pub struct Octree {
    nodes: Vec<Node>,
    order: Vec<usize>,
    sources: Vec<Source>,
    area_each: f64,
}

const LEAF: usize = 8;
const MAX_DEPTH: usize = 24;

fn dist2(a: [f64; 3], b: [f64; 3]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum()
}

impl Octree {
    /// `area_each`: the area (mm²) each source stands for.
    pub fn build(sources: Vec<Source>, area_each: f64) -> Octree {
        let mut t = Octree {
            nodes: Vec::new(),
            order: (0..sources.len()).collect(),
            sources,
            area_each,
        };
        if !t.sources.is_empty() {
            let n = t.sources.len();
            t.split(0, n, 0);
        }
        t
    }

    fn split(&mut self, first: usize, count: usize, depth: usize) -> usize {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        let mut power = [0.0; 3];
        let mut centre = [0.0; 3];
        let mut normal = [0.0; 3];
        let mut weight = 0.0;
        for &i in &self.order[first..first + count] {
            let s = &self.sources[i];
            // Weight by the luminous power, with a floor so unlit regions still have a centre.
            let w = s.power.iter().sum::<f64>() + 1e-30;
            for k in 0..3 {
                lo[k] = lo[k].min(s.p[k]);
                hi[k] = hi[k].max(s.p[k]);
                power[k] += s.power[k];
                centre[k] += w * s.p[k];
                normal[k] += w * s.n[k];
            }
            weight += w;
        }
        let id = self.nodes.len();
        self.nodes.push(Node {
            lo,
            hi,
            centre: centre.map(|c| c / weight),
            normal: crate::support::geometry::normalize(normal).unwrap_or([0.0; 3]),
            power,
            area: count as f64 * self.area_each,
            children: Vec::new(),
            first,
            count,
        });
        if count <= LEAF || depth >= MAX_DEPTH {
            return id;
        }
        let mid = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
        let octant =
            |p: [f64; 3]| (0..3).fold(0usize, |o, k| o | (((p[k] > mid[k]) as usize) << k));
        // Stable partition of this node's range by octant.
        let slice = &mut self.order[first..first + count];
        let sources = &self.sources;
        slice.sort_by_key(|&i| octant(sources[i].p));
        let mut start = first;
        let mut children = Vec::new();
        for o in 0..8 {
            let n = self.order[start..first + count]
                .iter()
                .take_while(|&&i| octant(self.sources[i].p) == o)
                .count();
            if n > 0 {
                if n == count {
                    // All points coincide in one octant (identical positions): stop here.
                    return id;
                }
                children.push(self.split(start, n, depth + 1));
                start += n;
            }
        }
        self.nodes[id].children = children;
        id
    }

    /// Σ Rd·power over sources at least `near` away from x, with far nodes lumped where
    /// ΔA/d² < `threshold`. `rd(p, n, d²)` returns Rd per channel for a source at p with normal n
    /// (a lumped node's mean) at squared distance d² from x. Returns the sum and how many terms
    /// were evaluated.
    pub fn gather(
        &self,
        x: [f64; 3],
        near: f64,
        threshold: f64,
        rd: &dyn Fn([f64; 3], [f64; 3], f64) -> [f64; 3],
    ) -> ([f64; 3], usize) {
        self.gather_keyed(x, near, threshold, &|_, p, n, d2| rd(p, n, d2))
    }

    /// [`Octree::gather`] whose `rd` also gets the term's key, its place in [`Octree::points`]:
    /// what a kernel derives from a source's position and normal alone can be made once per
    /// point instead of once per term.
    pub fn gather_keyed(
        &self,
        x: [f64; 3],
        near: f64,
        threshold: f64,
        rd: &dyn Fn(usize, [f64; 3], [f64; 3], f64) -> [f64; 3],
    ) -> ([f64; 3], usize) {
        let mut sum = [0.0; 3];
        let mut evaluated = 0;
        if self.nodes.is_empty() {
            return (sum, 0);
        }
        let near2 = near * near;
        let mut stack = vec![0usize];
        let add = |key: usize, p: [f64; 3], n: [f64; 3], power: [f64; 3], sum: &mut [f64; 3]| {
            let d2 = dist2(x, p);
            if d2 >= near2 {
                let r = rd(key, p, n, d2);
                for k in 0..3 {
                    sum[k] += r[k] * power[k];
                }
            }
        };
        // Sources are keyed after every node.
        let first_source = self.nodes.len();
        while let Some(id) = stack.pop() {
            let node = &self.nodes[id];
            let inside = (0..3).all(|k| x[k] >= node.lo[k] && x[k] <= node.hi[k]);
            let d2 = dist2(x, node.centre);
            // A node whose centre lies inside the near disc is opened, so that only its points
            // inside the disc are left out, as brute force does.
            if !inside && threshold > 0.0 && node.area < threshold * d2 && d2 >= near2 {
                add(id, node.centre, node.normal, node.power, &mut sum);
                evaluated += 1;
            } else if node.children.is_empty() {
                for &i in &self.order[node.first..node.first + node.count] {
                    let s = &self.sources[i];
                    add(first_source + i, s.p, s.n, s.power, &mut sum);
                    evaluated += 1;
                }
            } else {
                stack.extend(node.children.iter().rev());
            }
        }
        (sum, evaluated)
    }

    /// Every position and normal a term of [`Octree::gather_keyed`] can have, by key: the
    /// nodes' means, then the sources in their own order.
    pub fn points(&self) -> Vec<([f64; 3], [f64; 3])> {
        self.nodes
            .iter()
            .map(|n| (n.centre, n.normal))
            .chain(self.sources.iter().map(|s| (s.p, s.n)))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: usize) -> Vec<Source> {
        (0..n * n)
            .map(|i| Source {
                p: [(i % n) as f64, (i / n) as f64, 0.0],
                n: [0.0, 0.0, 1.0],
                power: [1.0, 0.5, 0.25],
            })
            .collect()
    }

    #[test]
    fn threshold_zero_is_brute_force_and_lumping_stays_close() {
        let sources = grid(40);
        let tree = Octree::build(sources.clone(), 1.0);
        let rd = |r: f64| {
            [
                (-0.3 * r).exp(),
                (-0.1 * r).exp() / (1.0 + r),
                1.0 / (1.0 + r * r),
            ]
        };
        let x = [12.3, 20.7, 0.5];
        let mut brute = [0.0; 3];
        for s in &sources {
            let r = rd(dist2(x, s.p).sqrt());
            for k in 0..3 {
                brute[k] += r[k] * s.power[k];
            }
        }
        let rd3 = |_: [f64; 3], _: [f64; 3], d2: f64| rd(d2.sqrt());
        let (exact, n) = tree.gather(x, 0.0, 0.0, &rd3);
        assert_eq!(n, 1600);
        for k in 0..3 {
            assert!((exact[k] - brute[k]).abs() < 1e-9 * brute[k]);
        }
        // Lumped: fewer terms, and the error shrinks with the threshold.
        let mut last = f64::INFINITY;
        for t in [0.5, 0.1, 0.02] {
            let (s, m) = tree.gather(x, 0.0, t, &rd3);
            let err = (0..3)
                .map(|k| ((s[k] - brute[k]) / brute[k]).abs())
                .fold(0.0, f64::max);
            assert!(
                m < 1600 && err <= last + 1e-12,
                "threshold {t}: {m} terms, error {err}"
            );
            last = err;
        }
        assert!(last < 1e-3, "{last}");
        // Points closer than `near` are left out.
        let (s, _) = tree.gather([0.0, 0.0, 0.0], 0.5, 0.0, &|_, _, _| [1.0; 3]);
        assert!((s[0] - 1599.0).abs() < 1e-9);
    }

    #[test]
    fn each_term_s_key_names_its_own_point() {
        // Normals vary, so a lumped node's mean differs from every source's.
        let sources: Vec<Source> = grid(20)
            .into_iter()
            .enumerate()
            .map(|(i, s)| Source {
                n: crate::support::geometry::normalize([(i % 7) as f64 * 0.1, 0.2, 1.0]).unwrap(),
                ..s
            })
            .collect();
        let tree = Octree::build(sources.clone(), 1.0);
        let points = tree.points();
        let wrong = std::sync::atomic::AtomicUsize::new(0);
        let seen = std::sync::Mutex::new(std::collections::HashSet::new());
        let x = [3.2, 17.9, 0.4];
        for threshold in [0.0, 0.05] {
            let (_, terms) = tree.gather_keyed(x, 0.0, threshold, &|key, p, n, _| {
                if points.get(key) != Some(&(p, n)) {
                    wrong.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                }
                seen.lock().unwrap().insert(key);
                [0.0; 3]
            });
            assert!(terms > 0);
        }
        assert_eq!(wrong.into_inner(), 0);
        // Brute force's keys are the sources themselves, one each, after the nodes'.
        let seen = seen.into_inner().unwrap();
        let nodes = points.len() - sources.len();
        assert!((nodes..points.len()).all(|k| seen.contains(&k)));
        assert!(seen.iter().any(|&k| k < nodes), "no lumped term at 0.05");
    }
}
