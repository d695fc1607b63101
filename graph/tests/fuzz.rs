//! Property-based fuzzing of the parser and the checker: arbitrary text, and graph-shaped JSON with
//! random ids, kinds, parameters and references (cycles, duplicates, dangling and malformed
//! references, values of every JSON type). Parsing and checking must return, never panic, and a
//! graph that passes must come out in an order where every node follows the nodes it reads.

use mesoflow_graph::{
    check, DevicePreference, GraphFile, InputSpec, KindSignature, OutputSpec, TypeSet,
};
use proptest::prelude::*;
use serde_json::{json, Map, Value};

fn catalog() -> Vec<KindSignature> {
    let sig =
        |kind: &str, inputs: &[(&str, &str, bool)], outputs: &[(&str, &str)], params: Value| {
            KindSignature {
                kind: kind.into(),
                version: 1,
                device: DevicePreference::Cpu,
                doc: String::new(),
                inputs: inputs
                    .iter()
                    .map(|(n, t, r)| InputSpec {
                        name: (*n).into(),
                        ty: TypeSet::one(t),
                        required: *r,
                        doc: String::new(),
                    })
                    .collect(),
                outputs: outputs
                    .iter()
                    .map(|(n, t)| OutputSpec {
                        name: (*n).into(),
                        ty: (*t).into(),
                        doc: String::new(),
                    })
                    .collect(),
                params,
                timings: vec![],
            }
        };
    vec![
        sig(
            "src",
            &[],
            &[("a", "A"), ("b", "B")],
            json!({"type": "object", "properties": {
                "size": {"type": "integer", "format": "uint32", "minimum": 1, "maximum": 4096},
                "mode": {"$ref": "#/$defs/Mode"},
                "path": {"type": "string", "x-output-path": true},
                "list": {"type": "array", "items": {"type": "number"}, "maxItems": 3}},
                "required": [],
                "$defs": {"Mode": {"oneOf": [{"const": "x"}, {"const": "y"}]}}}),
        ),
        sig(
            "map",
            &[("in", "A", true), ("opt", "B", false)],
            &[("a", "A")],
            json!({"type": "object", "properties": {"k": {"type": ["number", "null"], "exclusiveMinimum": 0}}}),
        ),
        sig(
            "sink",
            &[("x", "B", true)],
            &[("y", "A")],
            json!({"type": "object"}),
        ),
    ]
}

fn leaf() -> impl Strategy<Value = Value> {
    prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::Bool),
        any::<i64>().prop_map(|i| json!(i)),
        any::<u64>().prop_map(|u| json!(u)),
        any::<f64>()
            .prop_map(|f| serde_json::Number::from_f64(f).map_or(Value::Null, Value::Number)),
        "[a-z.\\-/ ]{0,12}".prop_map(Value::String),
    ]
}

fn value() -> impl Strategy<Value = Value> {
    leaf().prop_recursive(3, 24, 4, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..4).prop_map(Value::Array),
            prop::collection::btree_map("[a-z]{1,5}", inner, 0..4)
                .prop_map(|m| Value::Object(m.into_iter().collect())),
        ]
    })
}

/// A graph-shaped document: ids from a small pool (so references and duplicates often resolve),
/// kinds mostly from the catalog, parameters and inputs half plausible, half noise.
fn graph_doc() -> impl Strategy<Value = Value> {
    let id = prop_oneof!["[a-e]", "[A-Z0-9_\\-]{1,3}"];
    let kind = prop_oneof![Just("src"), Just("map"), Just("sink"), Just("nope")];
    let reference = prop_oneof![
        ("[a-e]", prop_oneof![Just("a"), Just("b"), Just("zz")])
            .prop_map(|(n, p)| json!(format!("{n}.{p}"))),
        "[a-e.]{0,5}".prop_map(|s| json!(s)),
        value(),
    ];
    let param = prop_oneof![
        Just("size"),
        Just("mode"),
        Just("path"),
        Just("list"),
        Just("k"),
        Just("other")
    ];
    let node = (
        kind,
        prop::collection::btree_map(param, value(), 0..4),
        prop::collection::btree_map(
            prop_oneof![Just("in"), Just("opt"), Just("x"), Just("q")],
            reference,
            0..3,
        ),
        any::<bool>(),
    )
        .prop_map(|(kind, params, inputs, noisy)| {
            let mut n = Map::new();
            n.insert("kind".into(), json!(kind));
            n.insert(
                "params".into(),
                Value::Object(
                    params
                        .into_iter()
                        .map(|(k, v)| (k.to_string(), v))
                        .collect(),
                ),
            );
            n.insert(
                "inputs".into(),
                Value::Object(
                    inputs
                        .into_iter()
                        .map(|(k, v)| (k.to_string(), v))
                        .collect(),
                ),
            );
            if noisy {
                n.insert("extra".into(), json!(1));
            }
            Value::Object(n)
        });
    (
        prop_oneof![Just(json!(1)), Just(json!(2)), value()],
        prop::collection::vec((id, node), 0..8),
    )
        .prop_map(|(version, nodes)| {
            let mut text = String::from("{\"mesoflow\": ");
            text.push_str(&version.to_string());
            text.push_str(", \"nodes\": {");
            // Written by hand so that duplicated ids stay in the text.
            for (i, (id, node)) in nodes.iter().enumerate() {
                if i > 0 {
                    text.push(',');
                }
                text.push_str(&format!("{}: {node}", json!(id)));
            }
            text.push_str("}}");
            Value::String(text)
        })
}

fn check_text(text: &str) {
    let Ok(file) = GraphFile::parse(text) else {
        return;
    };
    let cat = catalog();
    if let Ok(g) = check("fuzz.json", &file, &cat) {
        for (i, n) in g.nodes.iter().enumerate() {
            for e in &n.inputs {
                let j = g
                    .index(&e.from.node)
                    .expect("an input's node is in the graph");
                assert!(j < i, "{} reads {} which comes later", n.id, e.from.node);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 3000, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_text_is_refused_or_parsed_never_a_panic(text in "\\PC{0,200}") {
        check_text(&text);
    }

    #[test]
    fn graph_shaped_documents_are_checked_never_a_panic(doc in graph_doc()) {
        check_text(doc.as_str().unwrap());
    }
}
