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
            let id = match chained.and_then(|id| units.get_mut(&id).map(|u| (id, u))) {
                Some((id, unit)) => {
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

#[cfg(test)]
mod tests {
    use super::*;
    use mesoflow_runtime::{Engine, EngineConfig, RunOptions};

    fn variant(engine: &Engine, text: &str) -> (CheckedGraph, BTreeMap<String, Key>) {
        let file = mesoflow_graph::GraphFile::parse(text).unwrap();
        let graph = mesoflow_graph::check("g", &file, engine.registry()).unwrap();
        let opts = RunOptions::new("g", ".".into(), "out".into(), Default::default());
        let keys = engine
            .keys(&graph, &opts)
            .into_iter()
            .map(|(id, k)| (id, k.unwrap()))
            .collect();
        (graph, keys)
    }

    fn graph(scale_c: f64) -> String {
        // a → b → c and b → d: b has two consumers, so the chain from a stops at b.
        format!(
            r#"{{"mesoflow": 1, "nodes": {{
              "a": {{"kind": "scalar.constant", "params": {{"value": 1}}}},
              "b": {{"kind": "scalar.affine", "inputs": {{"x": "a.value"}}}},
              "c": {{"kind": "scalar.affine", "inputs": {{"x": "b.y"}}, "params": {{"scale": {scale_c}}}}},
              "d": {{"kind": "scalar.affine", "inputs": {{"x": "b.y"}}, "params": {{"offset": 1}}}}}}}}"#
        )
    }

    fn node_lists(units: &BTreeMap<String, UnitSpec>) -> Vec<Vec<String>> {
        let mut v: Vec<Vec<String>> = units.values().map(|u| u.nodes.clone()).collect();
        v.sort();
        v
    }

    #[test]
    fn chains_split_where_a_node_has_two_consumers_and_shared_keys_are_one_unit() {
        let engine = Engine::new(
            mesoflow_nodes::registry::builtin(),
            EngineConfig {
                memory_budget: 1 << 20,
                disk: None,
            },
        );
        let one = variant(&engine, &graph(2.0));
        let units = split(std::slice::from_ref(&one), &BTreeSet::new());
        let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        assert_eq!(
            node_lists(&units),
            vec![s(&["a", "b"]), s(&["c"]), s(&["d"])]
        );
        // The unit of c reads b's value.
        let c = units.values().find(|u| u.nodes == ["c"]).unwrap();
        assert_eq!(c.inputs, vec![one.1["b"].hex()]);
        // --split b: b alone.
        let split_b = split(
            std::slice::from_ref(&one),
            &BTreeSet::from(["b".to_string()]),
        );
        assert_eq!(split_b.len(), 4);
        // A second variant that differs only in c shares a, b and d: one more unit, for c.
        let two = variant(&engine, &graph(3.0));
        let both = split(&[one, two], &BTreeSet::new());
        assert_eq!(both.len(), 4);
        assert_eq!(both.values().filter(|u| u.nodes == ["c"]).count(), 2);
        assert_eq!(both.values().filter(|u| u.variant == 1).count(), 1);
    }

    #[test]
    fn dependants_follow_keys_transitively() {
        let engine = Engine::new(
            mesoflow_nodes::registry::builtin(),
            EngineConfig {
                memory_budget: 1 << 20,
                disk: None,
            },
        );
        let v = variant(&engine, &graph(2.0));
        let units = split(std::slice::from_ref(&v), &BTreeSet::from(["b".to_string()]));
        let a = units
            .iter()
            .find(|(_, u)| u.nodes == ["a"])
            .unwrap()
            .0
            .clone();
        assert_eq!(dependants(&units, &a).len(), 3);
        let c = units
            .iter()
            .find(|(_, u)| u.nodes == ["c"])
            .unwrap()
            .0
            .clone();
        assert!(dependants(&units, &c).is_empty());
    }
}
