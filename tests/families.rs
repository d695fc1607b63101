//! The scene families (`mesoflow_testkit::scenes`): the shipped template with a scene's `--set`s
//! is that scene's graph, for development and held-out seeds alike, so what the bench measures
//! and what a user runs from the printed command are the same graph.

use mesoflow_graph::{parse_override, GraphFile, NodeDecl};
use mesoflow_testkit::scenes::{self, Kind, TEMPLATE, TEMPLATE_RESOLUTION, TEMPLATE_SAMPLES};
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
    let template = parse(&std::fs::read_to_string(root.join(TEMPLATE)).expect("the template"));
    let zero = scenes::family(Kind::Translucent, 0);
    assert_eq!(
        nodes(&template),
        nodes(&parse(
            &zero
                .graph(TEMPLATE_RESOLUTION, TEMPLATE_SAMPLES)
                .to_string()
        )),
        "as written, the template is seed 0"
    );
    for seed in (0..24).chain(scenes::HELD_OUT..scenes::HELD_OUT + 8) {
        let scene = scenes::family(Kind::Translucent, seed);
        for (resolution, samples) in [(TEMPLATE_RESOLUTION, TEMPLATE_SAMPLES), ([32, 24], 16)] {
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
