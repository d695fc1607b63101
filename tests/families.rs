//! The scene families (`mesoflow_testkit::scenes`): each family's shipped template with a
//! scene's `--set`s is that scene's graph, for development and held-out seeds alike, so what the
//! bench measures and what a user runs from the printed command are the same graph. With
//! `MESOFLOW_WRITE_TEMPLATES=1` the test first writes each template's nodes from the generator.

use mesoflow_graph::{parse_override, GraphFile, NodeDecl};
use mesoflow_testkit::scenes::{self, Kind};
use std::collections::BTreeMap;
use std::path::Path;

fn nodes(file: &GraphFile) -> BTreeMap<String, NodeDecl> {
    file.nodes.iter().cloned().collect()
}

fn parse(text: &str) -> GraphFile {
    GraphFile::parse(text).unwrap_or_else(|e| panic!("{e:?}"))
}

#[test]
fn the_template_with_a_scenes_sets_is_that_scenes_graph() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for kind in Kind::ALL {
        let path = root.join(kind.template());
        let (resolution, samples) = (kind.resolution(), kind.samples());
        let zero = scenes::family(kind, 0);
        if std::env::var_os("MESOFLOW_WRITE_TEMPLATES").is_some() {
            // Rewrites the template's nodes from the generator (its description kept).
            let text = std::fs::read_to_string(&path).expect("the template");
            let mut file: serde_json::Value = serde_json::from_str(&text).expect("JSON");
            file["nodes"] = zero.graph(resolution, samples)["nodes"].clone();
            let out = serde_json::to_string_pretty(&file).expect("JSON") + "\n";
            std::fs::write(&path, out).expect("write the template");
        }
        let template = parse(&std::fs::read_to_string(&path).expect("the template"));
        assert_eq!(
            nodes(&template),
            nodes(&parse(&zero.graph(resolution, samples).to_string())),
            "as written, {} is seed 0",
            kind.template()
        );
        for seed in (0..24).chain(scenes::HELD_OUT..scenes::HELD_OUT + 8) {
            let scene = scenes::family(kind, seed);
            for (resolution, samples) in [(resolution, samples), ([32, 24], 4)] {
                let mut file = template.clone();
                for set in scene.sets(resolution, samples) {
                    let o = parse_override(&set).unwrap_or_else(|e| panic!("{set}: {e}"));
                    file.apply(&o).unwrap_or_else(|e| panic!("{set}: {e}"));
                }
                let drawn = parse(&scene.graph(resolution, samples).to_string());
                assert_eq!(nodes(&file), nodes(&drawn), "{}", scene.name());
            }
        }
    }
}
