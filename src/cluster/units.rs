//! Splitting runs into units of work for a cluster. A unit is, by default, a chain of nodes each
//! with one consumer (`--split` makes a node its own unit). Units are found across every variant
//! of a sweep at once and deduplicated by key: a node whose key an earlier variant already owns
//! is not computed again, so a shared upstream part is one unit.

use mesoflow_graph::CheckedGraph;
use mesoflow_runtime::Key;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

/// One unit: which variant's graph it belongs to, its nodes in topological order, their keys,
/// and the keys of the values it reads from other units.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnitSpec {
    pub variant: usize,
    pub nodes: Vec<String>,
    pub keys: Vec<String>,
    pub inputs: Vec<String>,
}

/// The units of `variants` (each a checked graph and the keys of its needed nodes), by id (the
/// first 16 hex digits of the unit's first key: stable across restarts of the driver).
pub fn split(
    variants: &[(CheckedGraph, BTreeMap<String, Key>)],
    split: &BTreeSet<String>,
) -> BTreeMap<String, UnitSpec> {
    let mut units: BTreeMap<String, UnitSpec> = BTreeMap::new();
    // Which unit computes a key.
    let mut owner: BTreeMap<Key, String> = BTreeMap::new();
    for (v, (graph, keys)) in variants.iter().enumerate() {
        // Consumers of each node among the needed ones.
        let mut consumers: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
        for n in graph.nodes.iter().filter(|n| keys.contains_key(&n.id)) {
            for e in &n.inputs {
                consumers
                    .entry(e.from.node.as_str())
                    .or_default()
                    .insert(n.id.as_str());
            }
        }
        // The unit each node of this variant was put in, when it was made in this variant.
        let mut here: BTreeMap<&str, String> = BTreeMap::new();
        for n in &graph.nodes {
            let Some(&key) = keys.get(&n.id) else {
                continue;
            };
            if owner.contains_key(&key) {
                continue; // computed by a unit of an earlier variant (or this one)
            }
            let upstream: BTreeSet<&str> = n.inputs.iter().map(|e| e.from.node.as_str()).collect();
            let chained = match upstream.iter().next() {
                Some(&u) if upstream.len() == 1 => here
                    .get(u)
                    .filter(|id| {
                        consumers.get(u).is_some_and(|c| c.len() == 1)
                            && !split.contains(u)
                            && !split.contains(&n.id)
                            && units[*id].nodes.last().map(String::as_str) == Some(u)
                    })
                    .cloned(),
                _ => None,
            };
            let id = match chained {
                Some(id) => {
                    let unit = units.get_mut(&id).expect("the unit was made above");
                    unit.nodes.push(n.id.clone());
                    unit.keys.push(key.hex());
                    id
                }
                None => {
                    let id = key.hex()[..16].to_string();
                    let inputs: Vec<String> = upstream
                        .iter()
                        .filter_map(|u| keys.get(*u).map(Key::hex))
                        .collect();
                    units.insert(
                        id.clone(),
                        UnitSpec {
                            variant: v,
                            nodes: vec![n.id.clone()],
                            keys: vec![key.hex()],
                            inputs,
                        },
                    );
                    id
                }
            };
            owner.insert(key, id.clone());
            here.insert(n.id.as_str(), id);
        }
    }
    units
}

/// The units that read, directly or not, a value of `failed`.
pub fn dependants(units: &BTreeMap<String, UnitSpec>, failed: &str) -> BTreeSet<String> {
    let mut dead: BTreeSet<String> = BTreeSet::from([failed.to_string()]);
    let mut dead_keys: BTreeSet<String> = units[failed].keys.iter().cloned().collect();
    loop {
        let mut grew = false;
        for (id, u) in units {
            if !dead.contains(id) && u.inputs.iter().any(|k| dead_keys.contains(k)) {
                dead.insert(id.clone());
                dead_keys.extend(u.keys.iter().cloned());
                grew = true;
            }
        }
        if !grew {
            break;
        }
    }
    dead.remove(failed);
    dead
}
