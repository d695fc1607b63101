//! Writing an edited graph back into its own text: only the values that changed are replaced,
//! so the file keeps its order, its layout (one-line nodes, aligned blocks) and everything a
//! person wrote around them. The studio saves through this; a diff of the saved file shows the
//! edit and nothing else.

use crate::file::{GraphFile, NodeDecl};
use serde_json::{Map, Value};

/// Where one JSON value lies in the text; objects keep their entries with the span of each key.
#[derive(Debug)]
enum Span {
    Object {
        start: usize,
        end: usize,
        entries: Vec<Entry>,
    },
    Other,
}

#[derive(Debug)]
struct Entry {
    key: String,
    key_start: usize,
    value_start: usize,
    value_end: usize,
    value: Span,
}

/// A recursive-descent scanner that records spans; it assumes text serde_json already accepted.
struct Scanner<'a> {
    b: &'a [u8],
    i: usize,
}

impl Scanner<'_> {
    fn ws(&mut self) {
        while self.i < self.b.len() && self.b[self.i].is_ascii_whitespace() {
            self.i += 1;
        }
    }

    fn string(&mut self) -> Option<String> {
        let start = self.i;
        if self.b.get(self.i) != Some(&b'"') {
            return None;
        }
        self.i += 1;
        while self.i < self.b.len() {
            match self.b[self.i] {
                b'\\' => self.i += 2,
                b'"' => {
                    self.i += 1;
                    let raw = std::str::from_utf8(&self.b[start..self.i]).ok()?;
                    return serde_json::from_str(raw).ok();
                }
                _ => self.i += 1,
            }
        }
        None
    }

    /// Scans one value; returns its span and leaves `i` just after it.
    fn value(&mut self) -> Option<Span> {
        self.ws();
        match self.b.get(self.i)? {
            b'{' => {
                let start = self.i;
                self.i += 1;
                let mut entries = Vec::new();
                loop {
                    self.ws();
                    if self.b.get(self.i) == Some(&b'}') {
                        self.i += 1;
                        return Some(Span::Object {
                            start,
                            end: self.i,
                            entries,
                        });
                    }
                    if self.b.get(self.i) == Some(&b',') {
                        self.i += 1;
                        continue;
                    }
                    let key_start = self.i;
                    let key = self.string()?;
                    self.ws();
                    if self.b.get(self.i) != Some(&b':') {
                        return None;
                    }
                    self.i += 1;
                    self.ws();
                    let value_start = self.i;
                    let value = self.value()?;
                    entries.push(Entry {
                        key,
                        key_start,
                        value_start,
                        value_end: self.i,
                        value,
                    });
                }
            }
            b'[' => {
                self.i += 1;
                loop {
                    self.ws();
                    match self.b.get(self.i)? {
                        b']' => {
                            self.i += 1;
                            return Some(Span::Other);
                        }
                        b',' => self.i += 1,
                        _ => {
                            self.value()?;
                        }
                    }
                }
            }
            b'"' => self.string().map(|_| Span::Other),
            _ => {
                while self.i < self.b.len() && !b",]} \t\r\n".contains(&self.b[self.i]) {
                    self.i += 1;
                }
                Some(Span::Other)
            }
        }
    }
}

fn scan(text: &str) -> Option<Span> {
    Scanner {
        b: text.as_bytes(),
        i: 0,
    }
    .value()
}

/// A value as the graph files write it by hand: `{ "a": 1, "b": [1, 2] }` on one line.
pub fn inline_json(v: &Value) -> String {
    match v {
        Value::Object(m) if m.is_empty() => "{}".into(),
        Value::Object(m) => {
            let parts: Vec<String> = m
                .iter()
                .map(|(k, x)| format!("{}: {}", Value::String(k.clone()), inline_json(x)))
                .collect();
            format!("{{ {} }}", parts.join(", "))
        }
        Value::Array(a) => {
            let parts: Vec<String> = a.iter().map(inline_json).collect();
            format!("[{}]", parts.join(", "))
        }
        other => other.to_string(),
    }
}

/// One replacement of a byte range.
struct Splice {
    start: usize,
    end: usize,
    with: String,
}

fn find<'s>(span: &'s Span, key: &str) -> Option<&'s Entry> {
    match span {
        Span::Object { entries, .. } => entries.iter().find(|e| e.key == key),
        Span::Other => None,
    }
}

/// The indentation of the line `at` lies on.
fn indent_at(text: &str, at: usize) -> &str {
    let line_start = text[..at].rfind('\n').map_or(0, |i| i + 1);
    let line = &text[line_start..];
    &line[..line.len() - line.trim_start().len()]
}

/// Adds `"key": value` at the end of an object, on a line of its own when the object's entries
/// are on lines of their own, else inline.
fn insert_entry(text: &str, obj: &Span, key: &str, value: &str, out: &mut Vec<Splice>) {
    let Span::Object {
        start,
        end,
        entries,
    } = obj
    else {
        return;
    };
    let entry = format!("{}: {value}", Value::String(key.into()));
    match entries.last() {
        None => out.push(Splice {
            start: *start,
            end: *end,
            with: format!("{{ {entry} }}"),
        }),
        Some(last) => {
            let between = &text[*start..last.key_start];
            let multiline = between.contains('\n');
            let with = if multiline {
                format!(",\n{}{entry}", indent_at(text, last.key_start))
            } else {
                format!(", {entry}")
            };
            out.push(Splice {
                start: last.value_end,
                end: last.value_end,
                with,
            });
        }
    }
}

/// Removes an entry with the comma that joins it to its neighbour.
fn remove_entry(obj: &Span, key: &str, out: &mut Vec<Splice>) {
    let Span::Object { entries, .. } = obj else {
        return;
    };
    let Some(i) = entries.iter().position(|e| e.key == key) else {
        return;
    };
    let (start, end) = if i > 0 {
        // From the end of the previous value: its comma and this entry go.
        (entries[i - 1].value_end, entries[i].value_end)
    } else if let Some(next) = entries.get(1) {
        (entries[0].key_start, next.key_start)
    } else {
        (entries[0].key_start, entries[0].value_end)
    };
    out.push(Splice {
        start,
        end,
        with: String::new(),
    });
}

/// Brings one member (`params` or `inputs`) of a node from `old` to `new`.
fn sync_object(
    text: &str,
    node: &Span,
    member: &str,
    old: &Map<String, Value>,
    new: &Map<String, Value>,
    out: &mut Vec<Splice>,
) {
    if old == new {
        return;
    }
    let Some(entry) = find(node, member) else {
        insert_entry(
            text,
            node,
            member,
            &inline_json(&Value::Object(new.clone())),
            out,
        );
        return;
    };
    for (k, v) in new {
        match (old.get(k), find(&entry.value, k)) {
            (Some(x), _) if x == v => {}
            (_, Some(e)) => out.push(Splice {
                start: e.value_start,
                end: e.value_end,
                with: inline_json(v),
            }),
            (_, None) => insert_entry(text, &entry.value, k, &inline_json(v), out),
        }
    }
    for k in old.keys().filter(|k| !new.contains_key(*k)) {
        remove_entry(&entry.value, k, out);
    }
}

fn node_json(d: &NodeDecl) -> Value {
    let mut obj = Map::new();
    obj.insert("kind".into(), Value::String(d.kind.clone()));
    if !d.inputs.is_empty() {
        obj.insert("inputs".into(), Value::Object(inputs_map(d)));
    }
    if !d.params.is_empty() {
        obj.insert("params".into(), Value::Object(d.params.clone()));
    }
    Value::Object(obj)
}

fn inputs_map(d: &NodeDecl) -> Map<String, Value> {
    d.inputs
        .iter()
        .map(|(k, v)| (k.clone(), Value::String(v.clone())))
        .collect()
}

/// `text` (a graph file that parses as `old`) rewritten to hold `new`, changing only what
/// differs. Falls back to [`GraphFile::to_json`] where the text cannot be edited in place (it
/// does not parse as `old`, or the edit would not read back as `new`).
pub fn rewrite(text: &str, old: &GraphFile, new: &GraphFile) -> String {
    edit_in_place(text, old, new)
        .filter(|t| GraphFile::parse(t).is_ok_and(|g| g == *new))
        .unwrap_or_else(|| new.to_json() + "\n")
}

fn edit_in_place(text: &str, old: &GraphFile, new: &GraphFile) -> Option<String> {
    if GraphFile::parse(text).ok()? != *old
        || old.description != new.description
        || old.interface != new.interface
    {
        return None;
    }
    let root = scan(text)?;
    let nodes = &find(&root, "nodes")?.value;
    let mut out = Vec::new();
    for (id, _) in &old.nodes {
        if new.node(id).is_none() {
            remove_entry(nodes, id, &mut out);
        }
    }
    for (id, decl) in &new.nodes {
        let Some(before) = old.node(id) else {
            insert_entry(text, nodes, id, &inline_json(&node_json(decl)), &mut out);
            continue;
        };
        let span = &find(nodes, id)?.value;
        if before.kind != decl.kind {
            let e = find(nodes, id)?;
            out.push(Splice {
                start: e.value_start,
                end: e.value_end,
                with: inline_json(&node_json(decl)),
            });
            continue;
        }
        sync_object(text, span, "params", &before.params, &decl.params, &mut out);
        sync_object(
            text,
            span,
            "inputs",
            &inputs_map(before),
            &inputs_map(decl),
            &mut out,
        );
    }
    // Applied from the end, so earlier offsets stay valid; of several insertions at one offset
    // the last goes in first, so they read in the order they were made.
    let mut out: Vec<(usize, Splice)> = out.into_iter().enumerate().collect();
    out.sort_by_key(|(i, s)| std::cmp::Reverse((s.start, s.end, *i)));
    let mut result = text.to_string();
    let mut last_start = usize::MAX;
    for (_, s) in out {
        if s.end > last_start {
            return None; // overlapping edits: leave it to the fallback
        }
        result.replace_range(s.start..s.end, &s.with);
        last_start = s.start;
    }
    Some(result)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    const TEXT: &str = r#"{
  "mesoflow": 1,
  "description": "test",
  "nodes": {
    "surface": {
      "kind": "heightfield.procedural",
      "params": { "pattern": "weave", "size": 256, "count": 8 }
    },
    "normals": { "kind": "heightfield.normals", "inputs": { "height": "surface.height" } },
    "save": { "kind": "image.write", "inputs": { "image": "normals.preview" }, "params": { "path": "n.png" } }
  }
}
"#;

    fn parsed(t: &str) -> GraphFile {
        GraphFile::parse(t).expect("test graph parses")
    }

    #[test]
    fn a_changed_parameter_changes_one_token() {
        let old = parsed(TEXT);
        let mut new = old.clone();
        new.node_mut("surface").unwrap().params["size"] = json!(64);
        let out = rewrite(TEXT, &old, &new);
        assert_eq!(out, TEXT.replace("\"size\": 256", "\"size\": 64"));
    }

    #[test]
    fn an_unchanged_graph_is_written_byte_for_byte() {
        let old = parsed(TEXT);
        assert_eq!(rewrite(TEXT, &old, &old), TEXT);
    }

    #[test]
    fn added_params_nodes_and_removed_ones_keep_the_layout() {
        let old = parsed(TEXT);
        let mut new = old.clone();
        new.node_mut("normals")
            .unwrap()
            .params
            .insert("strength".into(), json!(2.0));
        let surface = new.node_mut("surface").unwrap();
        surface.params.insert("depth".into(), json!(6));
        surface.params.insert("seed".into(), json!(1));
        new.node_mut("surface")
            .unwrap()
            .params
            .shift_remove("count");
        new.nodes.retain(|(id, _)| id != "save");
        new.nodes.push((
            "png".into(),
            NodeDecl {
                kind: "image.write".into(),
                params: [("path".to_string(), json!("x.png"))].into_iter().collect(),
                inputs: [("image".to_string(), "normals.preview".to_string())]
                    .into_iter()
                    .collect(),
            },
        ));
        let out = rewrite(TEXT, &old, &new);
        assert_eq!(parsed(&out), new);
        let expected = r#"{
  "mesoflow": 1,
  "description": "test",
  "nodes": {
    "surface": {
      "kind": "heightfield.procedural",
      "params": { "pattern": "weave", "size": 256, "depth": 6, "seed": 1 }
    },
    "normals": { "kind": "heightfield.normals", "inputs": { "height": "surface.height" }, "params": { "strength": 2.0 } },
    "png": { "kind": "image.write", "inputs": { "image": "normals.preview" }, "params": { "path": "x.png" } }
  }
}
"#;
        assert_eq!(out, expected);
    }

    #[test]
    fn a_text_that_is_not_the_old_graph_is_rewritten_whole() {
        let old = parsed(TEXT);
        let mut new = old.clone();
        new.node_mut("surface").unwrap().params["size"] = json!(64);
        let other = TEXT.replace("256", "128");
        let out = rewrite(&other, &old, &new);
        assert_eq!(parsed(&out), new);
        assert_eq!(out, new.to_json() + "\n");
    }

    #[test]
    fn escaped_strings_and_nested_values_are_scanned() {
        let t = r#"{"mesoflow":1,"description":"a \"quoted\" {brace}","nodes":{"a":{"kind":"k","params":{"o":{"x":[1,{"y":2}]},"s":"]}"}}}}"#;
        let old = parsed(t);
        let mut new = old.clone();
        new.node_mut("a").unwrap().params["s"] = json!("z");
        let out = rewrite(t, &old, &new);
        assert_eq!(out, t.replace(r#""s":"]}""#, r#""s":"z""#));
    }
}
