//! The static check: everything that can be known wrong about a graph before it runs, reported all
//! at once. A graph that passes becomes a [`CheckedGraph`]: nodes in a topological order, each input
//! resolved to the output it reads.

use crate::catalog::Catalog;
use crate::error::{GraphError, GraphErrors};
use crate::file::{GraphFile, NodeDecl, PortRef};
use crate::params::check_params;
use petgraph::graphmap::DiGraphMap;
use serde_json::{Map, Value};
use std::collections::{BTreeMap, BTreeSet, HashMap};

/// A connection into an input port.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Edge {
    pub port: String,
    pub from: PortRef,
}

#[derive(Clone, Debug)]
pub struct CheckedNode {
    pub id: String,
    pub kind: String,
    pub params: Map<String, Value>,
    /// Sorted by port name.
    pub inputs: Vec<Edge>,
}

/// A graph that passed the static check.
#[derive(Clone, Debug)]
pub struct CheckedGraph {
    pub description: Option<String>,
    /// Topological order (every node after the nodes it reads); ties keep file order.
    pub nodes: Vec<CheckedNode>,
    /// The file's `expected_warnings`: a run marks those warnings expected in its report.
    pub expected_warnings: BTreeMap<String, Vec<String>>,
}

impl CheckedGraph {
    pub fn index(&self, id: &str) -> Option<usize> {
        self.nodes.iter().position(|n| n.id == id)
    }

    /// Nodes whose outputs no other node reads: what a run produces by default.
    pub fn sinks(&self) -> Vec<&str> {
        let read: BTreeSet<&str> = self
            .nodes
            .iter()
            .flat_map(|n| n.inputs.iter().map(|e| e.from.node.as_str()))
            .collect();
        self.nodes
            .iter()
            .map(|n| n.id.as_str())
            .filter(|id| !read.contains(id))
            .collect()
    }
}

/// Checks a parsed file against a catalog of kinds.
pub fn check(
    file_name: &str,
    file: &GraphFile,
    catalog: &dyn Catalog,
) -> Result<CheckedGraph, GraphErrors> {
    // Subgraphs are checked as if inlined: every node under its path (`pipeline/pca`).
    let expanded;
    let file = if crate::subgraph::uses_subgraphs(file) {
        expanded = crate::subgraph::expand(file).map_err(|errors| GraphErrors {
            file: file_name.into(),
            errors,
        })?;
        &expanded
    } else {
        file
    };
    let mut errors = Vec::new();
    let ids: Vec<&str> = file.nodes.iter().map(|(id, _)| id.as_str()).collect();
    // Looked up once per input: a map keeps the check linear in the size of the file (a linear
    // search per input made a 200 000-node file take minutes).
    let by_id: HashMap<&str, &NodeDecl> = file
        .nodes
        .iter()
        .rev() // the first declaration of a duplicated id wins, as `GraphFile::node` finds it
        .map(|(id, d)| (id.as_str(), d))
        .collect();
    let mut edges: Vec<(String, String)> = Vec::new();

    for (id, decl) in &file.nodes {
        let Some(sig) = catalog.signature(&decl.kind) else {
            errors.push(GraphError::UnknownKind {
                node: id.clone(),
                kind: decl.kind.clone(),
                suggestion: crate::nearest(&decl.kind, catalog.kinds()),
            });
            continue;
        };
        let param_errors = check_params(id, &sig.kind, &sig.params, &decl.params);
        if param_errors.is_empty() {
            errors.extend(check_typed(catalog, id, sig, &decl.params));
        }
        errors.extend(param_errors);
        for input in &sig.inputs {
            if input.required && !decl.inputs.contains_key(&input.name) {
                errors.push(GraphError::MissingInput {
                    node: id.clone(),
                    port: input.name.clone(),
                    ty: input.ty.to_string(),
                });
            }
        }
        for (port, reference) in &decl.inputs {
            let Some(spec) = sig.input(port) else {
                errors.push(GraphError::UnknownInput {
                    node: id.clone(),
                    kind: sig.kind.clone(),
                    port: port.clone(),
                    suggestion: crate::nearest(port, sig.inputs.iter().map(|p| p.name.as_str())),
                });
                continue;
            };
            let Some(from) = PortRef::parse(reference) else {
                errors.push(GraphError::BadReference {
                    node: id.clone(),
                    port: port.clone(),
                    reference: reference.clone(),
                });
                continue;
            };
            let Some(target) = by_id.get(from.node.as_str()) else {
                errors.push(GraphError::NoSuchNode {
                    node: id.clone(),
                    port: port.clone(),
                    target: from.node.clone(),
                    suggestion: crate::nearest(&from.node, ids.iter().copied()),
                });
                continue;
            };
            edges.push((from.node.clone(), id.clone()));
            // An unknown target kind was already reported on the target itself.
            let Some(target_sig) = catalog.signature(&target.kind) else {
                continue;
            };
            match target_sig.output(&from.port) {
                None => errors.push(GraphError::NoSuchOutput {
                    node: id.clone(),
                    port: port.clone(),
                    target: from.node.clone(),
                    target_port: from.port.clone(),
                    kind: target_sig.kind.clone(),
                    suggestion: crate::nearest(
                        &from.port,
                        target_sig.outputs.iter().map(|p| p.name.as_str()),
                    ),
                }),
                Some(out) if !spec.ty.accepts(&out.ty) => errors.push(GraphError::TypeMismatch {
                    node: id.clone(),
                    port: port.clone(),
                    expected: spec.ty.to_string(),
                    found: out.ty.clone(),
                    from: from.to_string(),
                }),
                Some(_) => {}
            }
        }
    }

    let order = match topological_order(&ids, &edges) {
        Ok(order) => order,
        Err(cycles) => {
            errors.extend(cycles.into_iter().map(|nodes| GraphError::Cycle { nodes }));
            Vec::new()
        }
    };
    if !errors.is_empty() {
        return Err(GraphErrors {
            file: file_name.to_string(),
            errors,
        });
    }
    let nodes = order
        .into_iter()
        .filter_map(|id| {
            let decl = by_id.get(id)?;
            let inputs = decl
                .inputs
                .iter()
                .filter_map(|(port, r)| {
                    Some(Edge {
                        port: port.clone(),
                        from: PortRef::parse(r)?,
                    })
                })
                .collect();
            Some(CheckedNode {
                id: id.to_string(),
                kind: decl.kind.clone(),
                params: decl.params.clone(),
                inputs,
            })
        })
        .collect();
    Ok(CheckedGraph {
        description: file.description.clone(),
        nodes,
        expected_warnings: file.expected_warnings.clone(),
    })
}

/// What the schema cannot say: the catalog's typed check. A problem that names its parameter is
/// reported as it is; otherwise each parameter is tried alone (with the required ones) so the
/// error names the parameter at fault.
fn check_typed(
    catalog: &dyn Catalog,
    node: &str,
    sig: &crate::catalog::KindSignature,
    params: &Map<String, Value>,
) -> Option<GraphError> {
    let problem = catalog.check_typed(&sig.kind, params).err()?;
    if let Some(param) = problem.param {
        return Some(GraphError::ParamInvalid {
            node: node.into(),
            param,
            message: problem.message,
        });
    }
    let message = problem.message;
    let required = sig.required_params();
    let culprit = params.iter().find_map(|(name, value)| {
        let mut alone: Map<String, Value> = params
            .iter()
            .filter(|(k, _)| required.contains(&k.as_str()))
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        alone.insert(name.clone(), value.clone());
        catalog
            .check_typed(&sig.kind, &alone)
            .err()
            .map(|p| (name.clone(), p.message))
    });
    let (param, mut message) = culprit.unwrap_or(("params".into(), message));
    // serde's words ("did not match any variant of untagged enum …") say what failed, the schema
    // says what would do.
    if let Some(sub) = sig.params.get("properties").and_then(|p| p.get(&param)) {
        message = format!(
            "{message}; expected {}",
            crate::params::expected_text(&sig.params, sub)
        );
    }
    Some(GraphError::ParamInvalid {
        node: node.into(),
        param,
        message,
    })
}

/// Kahn's algorithm, taking the earliest ready node in file order so that the order is stable.
/// On a cycle, returns each strongly connected component that is a cycle, listed in cycle order.
fn topological_order<'a>(
    ids: &[&'a str],
    edges: &[(String, String)],
) -> Result<Vec<&'a str>, Vec<Vec<String>>> {
    let pos: BTreeMap<&str, usize> = ids.iter().enumerate().map(|(i, id)| (*id, i)).collect();
    let mut graph = DiGraphMap::<usize, ()>::new();
    for i in 0..ids.len() {
        graph.add_node(i);
    }
    for (a, b) in edges {
        if let (Some(&a), Some(&b)) = (pos.get(a.as_str()), pos.get(b.as_str())) {
            graph.add_edge(a, b, ());
        }
    }
    let mut indegree: Vec<usize> = (0..ids.len())
        .map(|i| {
            graph
                .neighbors_directed(i, petgraph::Direction::Incoming)
                .count()
        })
        .collect();
    let mut ready: BTreeSet<usize> = (0..ids.len()).filter(|&i| indegree[i] == 0).collect();
    let mut order = Vec::with_capacity(ids.len());
    while let Some(i) = ready.pop_first() {
        order.push(ids[i]);
        for j in graph.neighbors_directed(i, petgraph::Direction::Outgoing) {
            indegree[j] -= 1;
            if indegree[j] == 0 {
                ready.insert(j);
            }
        }
    }
    if order.len() == ids.len() {
        return Ok(order);
    }
    let cycles = petgraph::algo::tarjan_scc(&graph)
        .into_iter()
        .filter(|scc| scc.len() > 1 || graph.contains_edge(scc[0], scc[0]))
        .map(|scc| {
            cycle_path(&graph, &scc)
                .into_iter()
                .map(|i| ids[i].to_string())
                .collect()
        })
        .collect();
    Err(cycles)
}

/// Orders a strongly connected component along one cycle through it, starting at its first node
/// in file order, so the message reads as a path ("a -> b -> c -> a").
fn cycle_path(graph: &DiGraphMap<usize, ()>, scc: &[usize]) -> Vec<usize> {
    let members: BTreeSet<usize> = scc.iter().copied().collect();
    let start = *members.first().unwrap_or(&0);
    // Breadth-first search inside the component for the shortest path back to `start`.
    let mut prev: BTreeMap<usize, usize> = BTreeMap::new();
    let mut queue = std::collections::VecDeque::from([start]);
    while let Some(u) = queue.pop_front() {
        for v in graph.neighbors_directed(u, petgraph::Direction::Outgoing) {
            if !members.contains(&v) {
                continue;
            }
            if v == start {
                let mut path = vec![u];
                let mut cur = u;
                while cur != start {
                    cur = prev[&cur];
                    path.push(cur);
                }
                path.reverse();
                return path;
            }
            if let std::collections::btree_map::Entry::Vacant(e) = prev.entry(v) {
                e.insert(u);
                queue.push_back(v);
            }
        }
    }
    members.into_iter().collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalog::{DevicePreference, InputSpec, KindSignature, OutputSpec};
    use crate::ports::TypeSet;
    use serde_json::json;

    fn catalog() -> Vec<KindSignature> {
        let sig = |kind: &str, inputs: Vec<(&str, &str, bool)>, outputs: Vec<(&str, &str)>| {
            KindSignature {
                kind: kind.into(),
                version: 1,
                device: DevicePreference::Cpu,
                doc: String::new(),
                inputs: inputs
                    .into_iter()
                    .map(|(n, t, r)| InputSpec {
                        name: n.into(),
                        ty: TypeSet::one(t),
                        required: r,
                        doc: String::new(),
                    })
                    .collect(),
                outputs: outputs
                    .into_iter()
                    .map(|(n, t)| OutputSpec {
                        name: n.into(),
                        ty: t.into(),
                        doc: String::new(),
                    })
                    .collect(),
                params: json!({"type": "object", "properties": {"size": {"type": "integer", "minimum": 1}}}),
                timings: vec![],
            }
        };
        vec![
            sig("surface", vec![], vec![("height", "HeightField")]),
            sig(
                "pca",
                vec![("btf", "Btf", true)],
                vec![("basis", "BtfBasis")],
            ),
            sig(
                "render",
                vec![("btf", "BtfBasis", true), ("env", "Image", false)],
                vec![("image", "Image")],
            ),
            sig("pass", vec![("x", "Image", true)], vec![("y", "Image")]),
        ]
    }

    fn run(text: &str) -> Result<CheckedGraph, GraphErrors> {
        check("g.json", &GraphFile::parse(text).unwrap(), &catalog())
    }

    #[test]
    fn type_mismatch_message_matches_the_brief() {
        let e = run(r#"{"mesoflow":1,"nodes":{"surface":{"kind":"surface"},
            "render":{"kind":"render","inputs":{"btf":"surface.height"}}}}"#)
        .unwrap_err();
        assert_eq!(
            e.errors[0].to_string(),
            "`render` input `btf` expects BtfBasis, got HeightField from `surface.height`"
        );
    }

    #[test]
    fn cycles_are_listed_in_order() {
        let e = run(
            r#"{"mesoflow":1,"nodes":{"a":{"kind":"pass","inputs":{"x":"c.y"}},
            "b":{"kind":"pass","inputs":{"x":"a.y"}},"c":{"kind":"pass","inputs":{"x":"b.y"}}}}"#,
        )
        .unwrap_err();
        assert_eq!(
            e.errors,
            vec![GraphError::Cycle {
                nodes: vec!["a".into(), "b".into(), "c".into()]
            }]
        );
        assert_eq!(e.errors[0].to_string(), "cycle: a -> b -> c -> a");
    }

    #[test]
    fn order_is_topological_and_sinks_are_found() {
        let g = run(
            r#"{"mesoflow":1,"nodes":{"render":{"kind":"render","inputs":{"btf":"pca.basis"}},
            "pca":{"kind":"pca","inputs":{"btf":"surface.height"}},"surface":{"kind":"surface"}}}"#,
        );
        // pca reads a HeightField where it wants a Btf: one error, and nothing else wrong.
        assert_eq!(g.unwrap_err().errors.len(), 1);
        let g = run(
            r#"{"mesoflow":1,"nodes":{"p2":{"kind":"pass","inputs":{"x":"p1.y"}},
            "p1":{"kind":"pass","inputs":{"x":"r.image"}},"r":{"kind":"render","inputs":{"btf":"q.basis"}},
            "q":{"kind":"pca","inputs":{"btf":"s.height"}},"s":{"kind":"surface"}}}"#,
        );
        let err = g.unwrap_err();
        assert_eq!(err.errors.len(), 1, "{err}");
    }

    #[test]
    fn all_errors_are_reported_together() {
        let e = run(r#"{"mesoflow":1,"nodes":{
            "s":{"kind":"surfase","params":{}},
            "r":{"kind":"render","inputs":{"btff":"s.height","env":"nowhere.image"}},
            "t":{"kind":"surface","params":{"size":0,"sise":2}}}}"#)
        .unwrap_err();
        let nodes: Vec<_> = e
            .errors
            .iter()
            .map(|e| (e.node().unwrap(), e.field().unwrap()))
            .collect();
        assert_eq!(
            nodes,
            vec![
                ("s", "kind"),
                ("r", "btf"),
                ("r", "btff"),
                ("r", "env"),
                ("t", "size"),
                ("t", "sise")
            ]
        );
    }
}
