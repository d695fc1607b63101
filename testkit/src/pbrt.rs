//! A checker of pbrt-v4 scene files (pbrt itself is not installable here): the tokens and
//! statements of pbrt's scene-file grammar, the parameter lists' types and value counts, the
//! block structure (options, then `WorldBegin` once, then the world; balanced
//! `AttributeBegin`/`AttributeEnd`), names used only after they are made (materials, textures,
//! media), files named relative to the scene file present, and, for the plugins mesoflow's
//! `export.pbrt` writes, each parameter's name and type as pbrt-v4's file-format documentation
//! lists them, so a misspelt parameter that pbrt would warn about and ignore is refused.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

#[derive(Clone, Debug, PartialEq)]
enum Token {
    Word(String),
    Str(String),
    Open,
    Close,
}

fn tokens(text: &str) -> Result<Vec<(usize, Token)>, String> {
    let mut out = Vec::new();
    let mut chars = text.char_indices().peekable();
    let line_of = |at: usize| text[..at].matches('\n').count() + 1;
    while let Some(&(at, c)) = chars.peek() {
        match c {
            c if c.is_whitespace() => {
                chars.next();
            }
            '#' => {
                while chars.peek().is_some_and(|&(_, c)| c != '\n') {
                    chars.next();
                }
            }
            '[' | ']' => {
                chars.next();
                out.push((
                    line_of(at),
                    if c == '[' { Token::Open } else { Token::Close },
                ));
            }
            '"' => {
                chars.next();
                let mut s = String::new();
                loop {
                    match chars.next() {
                        Some((_, '"')) => break,
                        Some((_, '\n')) | None => {
                            return Err(format!("line {}: a string is not closed", line_of(at)))
                        }
                        Some((_, c)) => s.push(c),
                    }
                }
                out.push((line_of(at), Token::Str(s)));
            }
            _ => {
                let mut s = String::new();
                while let Some(&(_, c)) = chars.peek() {
                    if c.is_whitespace() || matches!(c, '[' | ']' | '"' | '#') {
                        break;
                    }
                    s.push(c);
                    chars.next();
                }
                out.push((line_of(at), Token::Word(s)));
            }
        }
    }
    Ok(out)
}

/// One parameter: its type, name and values (numbers and bools as written, strings unquoted).
#[derive(Clone, Debug)]
pub struct Param {
    pub ty: String,
    pub name: String,
    pub values: Vec<String>,
}

/// One statement: the directive, its positional arguments and its parameters.
#[derive(Clone, Debug)]
pub struct Statement {
    pub line: usize,
    pub directive: String,
    pub args: Vec<String>,
    pub params: Vec<Param>,
}

impl Statement {
    pub fn param(&self, name: &str) -> Option<&Param> {
        self.params.iter().find(|p| p.name == name)
    }
    /// The first value of parameter `name` as a number.
    pub fn number(&self, name: &str) -> Option<f64> {
        self.param(name)?.values.first()?.parse().ok()
    }
}

/// Directives and how many positional arguments they take: (numbers, strings, parameters).
fn shape_of(directive: &str) -> Option<(usize, usize, bool)> {
    Some(match directive {
        "Identity" | "ReverseOrientation" | "WorldBegin" | "AttributeBegin" | "AttributeEnd"
        | "ObjectEnd" => (0, 0, false),
        "Translate" | "Scale" => (3, 0, false),
        "Rotate" => (4, 0, false),
        "LookAt" => (9, 0, false),
        "CoordinateSystem" | "CoordSysTransform" | "NamedMaterial" | "ObjectBegin"
        | "ObjectInstance" | "Include" | "Import" | "ColorSpace" => (0, 1, false),
        "Camera" | "Sampler" | "Film" | "PixelFilter" | "Integrator" | "Accelerator"
        | "LightSource" | "AreaLightSource" | "Material" | "Shape" | "MakeNamedMaterial"
        | "MakeNamedMedium" | "Attribute" => (0, 1, true),
        "Texture" => (0, 3, true),
        "Option" => (0, 0, true),
        _ => return None,
    })
}

/// The directives that belong before `WorldBegin` (camera, film, sampling) and after it.
const OPTIONS: [&str; 6] = [
    "Camera",
    "Sampler",
    "Film",
    "PixelFilter",
    "Integrator",
    "Accelerator",
];
const WORLD: [&str; 10] = [
    "Shape",
    "LightSource",
    "AreaLightSource",
    "Material",
    "NamedMaterial",
    "MakeNamedMaterial",
    "Texture",
    "AttributeBegin",
    "AttributeEnd",
    "MediumInterface",
];

/// Parses a scene file's text into statements, checking the grammar.
pub fn parse(text: &str) -> Result<Vec<Statement>, String> {
    let toks = tokens(text)?;
    let mut i = 0;
    let mut out = Vec::new();
    while i < toks.len() {
        let (line, tok) = &toks[i];
        let Token::Word(directive) = tok else {
            return Err(format!("line {line}: expected a directive, found {tok:?}"));
        };
        i += 1;
        let mut st = Statement {
            line: *line,
            directive: directive.clone(),
            args: Vec::new(),
            params: Vec::new(),
        };
        if directive == "MediumInterface" {
            // One name (inside and outside alike) or two.
            while let Some((_, Token::Str(s))) = toks.get(i) {
                if st.args.len() == 2 {
                    break;
                }
                st.args.push(s.clone());
                i += 1;
            }
            if st.args.is_empty() {
                return Err(format!(
                    "line {line}: MediumInterface needs one or two names"
                ));
            }
            out.push(st);
            continue;
        }
        let Some((numbers, strings, has_params)) = shape_of(directive) else {
            return Err(format!(
                "line {line}: `{directive}` is not a pbrt-v4 directive"
            ));
        };
        for _ in 0..numbers {
            match toks.get(i) {
                Some((_, Token::Word(w))) if w.parse::<f64>().is_ok() => st.args.push(w.clone()),
                other => {
                    return Err(format!(
                        "line {line}: `{directive}` takes {numbers} numbers, found {other:?}"
                    ))
                }
            }
            i += 1;
        }
        for _ in 0..strings {
            match toks.get(i) {
                Some((_, Token::Str(s))) => st.args.push(s.clone()),
                other => {
                    return Err(format!(
                        "line {line}: `{directive}` takes {strings} quoted names, found {other:?}"
                    ))
                }
            }
            i += 1;
        }
        if has_params {
            while let Some((pline, Token::Str(decl))) = toks.get(i) {
                i += 1;
                let parts: Vec<&str> = decl.split_whitespace().collect();
                let [ty, name] = parts[..] else {
                    return Err(format!(
                        "line {pline}: parameter \"{decl}\" is not \"type name\""
                    ));
                };
                // Each value, and whether it was quoted (a string) or bare (a number, a bool).
                let (mut values, mut quoted) = (Vec::new(), Vec::new());
                let mut push = |t: &Token| -> Result<(), String> {
                    match t {
                        Token::Word(w) | Token::Str(w) => {
                            values.push(w.clone());
                            quoted.push(matches!(t, Token::Str(_)));
                            Ok(())
                        }
                        _ => Err(format!("line {pline}: \"{decl}\": unexpected {t:?}")),
                    }
                };
                match toks.get(i) {
                    Some((_, Token::Open)) => {
                        i += 1;
                        loop {
                            match toks.get(i) {
                                Some((_, Token::Close)) => {
                                    i += 1;
                                    break;
                                }
                                Some((_, t)) => {
                                    push(t)?;
                                    i += 1;
                                }
                                None => {
                                    return Err(format!("line {pline}: \"{decl}\": `[` not closed"))
                                }
                            }
                        }
                    }
                    Some((_, t)) => {
                        push(t)?;
                        i += 1;
                    }
                    None => return Err(format!("line {pline}: \"{decl}\" has no value")),
                }
                check_values(*pline, ty, name, &values, &quoted)?;
                st.params.push(Param {
                    ty: ty.to_string(),
                    name: name.to_string(),
                    values,
                });
            }
        }
        out.push(st);
    }
    Ok(out)
}

fn check_values(
    line: usize,
    ty: &str,
    name: &str,
    v: &[String],
    quoted: &[bool],
) -> Result<(), String> {
    let bad = |why: &str| Err(format!("line {line}: \"{ty} {name}\": {why} ({v:?})"));
    let numbers = || quoted.iter().all(|q| !q) && v.iter().all(|x| x.parse::<f64>().is_ok());
    if v.is_empty() {
        return bad("no values");
    }
    match ty {
        "integer" => {
            if quoted.iter().any(|q| *q) || v.iter().any(|x| x.parse::<i64>().is_err()) {
                return bad("integers expected");
            }
        }
        "float" => {
            if !numbers() {
                return bad("numbers expected");
            }
        }
        "point2" | "vector2" => {
            if !numbers() || !v.len().is_multiple_of(2) {
                return bad("pairs of numbers expected");
            }
        }
        "point3" | "vector3" | "normal3" | "normal" | "point" | "vector" => {
            if !numbers() || !v.len().is_multiple_of(3) {
                return bad("triples of numbers expected");
            }
        }
        "rgb" => {
            if !numbers() || v.len() != 3 {
                return bad("three numbers expected");
            }
        }
        "blackbody" => {
            if !numbers() || v.len() != 1 {
                return bad("one temperature expected");
            }
        }
        "spectrum" => {
            let named = v.len() == 1 && quoted[0];
            if !named && (!numbers() || !v.len().is_multiple_of(2)) {
                return bad("(wavelength, value) pairs or a quoted name expected");
            }
        }
        "bool" => {
            if v.iter().any(|x| x != "true" && x != "false") {
                return bad("true or false expected");
            }
        }
        "string" | "texture" => {
            if quoted.iter().any(|q| !q) {
                return bad("quoted strings expected");
            }
        }
        _ => return bad("not a pbrt-v4 parameter type"),
    }
    Ok(())
}

/// A parameter's types as pbrt-v4 reads them: "spectrum" admits rgb, spectrum and blackbody
/// values; "spectrum|texture" and "float|texture" a texture name too.
fn known(directive: &str, plugin: &str) -> Option<&'static [(&'static str, &'static str)]> {
    const SPECTRUM_TEX: &str = "spectrum|texture";
    const FLOAT_TEX: &str = "float|texture";
    Some(match (directive, plugin) {
        ("Camera", "perspective") => &[
            ("fov", "float"),
            ("lensradius", "float"),
            ("focaldistance", "float"),
            ("frameaspectratio", "float"),
            ("screenwindow", "float"),
            ("shutteropen", "float"),
            ("shutterclose", "float"),
        ],
        ("Camera", "orthographic") => &[
            ("lensradius", "float"),
            ("focaldistance", "float"),
            ("frameaspectratio", "float"),
            ("screenwindow", "float"),
            ("shutteropen", "float"),
            ("shutterclose", "float"),
        ],
        ("Sampler", "independent") => &[("pixelsamples", "integer"), ("seed", "integer")],
        ("Film", "rgb") => &[
            ("xresolution", "integer"),
            ("yresolution", "integer"),
            ("filename", "string"),
            ("cropwindow", "float"),
            ("pixelbounds", "integer"),
            ("diagonal", "float"),
            ("iso", "float"),
            ("whitebalance", "float"),
            ("sensor", "string"),
            ("maxcomponentvalue", "float"),
            ("savefp16", "bool"),
        ],
        ("PixelFilter", "box") => &[("xradius", "float"), ("yradius", "float")],
        ("Integrator", "path") | ("Integrator", "volpath") => &[
            ("maxdepth", "integer"),
            ("regularize", "bool"),
            ("lightsampler", "string"),
        ],
        ("LightSource", "distant") => &[
            ("from", "point3"),
            ("to", "point3"),
            ("L", "spectrum"),
            ("scale", "float"),
            ("illuminance", "float"),
        ],
        ("LightSource", "point") => &[
            ("from", "point3"),
            ("I", "spectrum"),
            ("scale", "float"),
            ("power", "float"),
        ],
        ("Material", "diffuse") => &[("reflectance", SPECTRUM_TEX), ("displacement", FLOAT_TEX)],
        ("Material", "conductor") => &[
            ("eta", SPECTRUM_TEX),
            ("k", SPECTRUM_TEX),
            ("reflectance", SPECTRUM_TEX),
            ("roughness", FLOAT_TEX),
            ("uroughness", FLOAT_TEX),
            ("vroughness", FLOAT_TEX),
            ("remaproughness", "bool"),
            ("displacement", FLOAT_TEX),
        ],
        ("Material", "dielectric") => &[
            ("eta", "float|spectrum"),
            ("roughness", FLOAT_TEX),
            ("uroughness", FLOAT_TEX),
            ("vroughness", FLOAT_TEX),
            ("remaproughness", "bool"),
            ("displacement", FLOAT_TEX),
        ],
        ("Material", "mix") => &[("materials", "string"), ("amount", FLOAT_TEX)],
        ("Material", "interface") => &[],
        ("Material", "subsurface") => &[
            ("eta", "float"),
            ("g", "float"),
            ("mfp", SPECTRUM_TEX),
            ("name", "string"),
            ("reflectance", SPECTRUM_TEX),
            ("sigma_a", SPECTRUM_TEX),
            ("sigma_s", SPECTRUM_TEX),
            ("scale", "float"),
            ("roughness", FLOAT_TEX),
            ("uroughness", FLOAT_TEX),
            ("vroughness", FLOAT_TEX),
            ("remaproughness", "bool"),
            ("displacement", FLOAT_TEX),
        ],
        ("Texture", "imagemap") => &[
            ("filename", "string"),
            ("uscale", "float"),
            ("vscale", "float"),
            ("udelta", "float"),
            ("vdelta", "float"),
            ("mapping", "string"),
            ("filter", "string"),
            ("wrap", "string"),
            ("encoding", "string"),
            ("scale", "float"),
            ("invert", "bool"),
            ("maxanisotropy", "float"),
        ],
        ("MakeNamedMedium", "homogeneous") => &[
            ("sigma_a", "spectrum"),
            ("sigma_s", "spectrum"),
            ("scale", "float"),
            ("g", "float"),
            ("Le", "spectrum"),
            ("Lescale", "float"),
            ("preset", "string"),
        ],
        ("Shape", "plymesh") => &[
            ("filename", "string"),
            ("displacement", FLOAT_TEX),
            ("edgelength", "float"),
        ],
        _ => return None,
    })
}

fn type_admits(allowed: &str, ty: &str) -> bool {
    allowed
        .split('|')
        .any(|a| a == ty || (a == "spectrum" && matches!(ty, "rgb" | "blackbody" | "spectrum")))
}

/// Checks one plugin's parameters against the table; `pbrt_directive` is the table's key
/// (`Material` for `MakeNamedMaterial`'s "string type").
fn check_plugin(
    st: &Statement,
    pbrt_directive: &str,
    plugin: &str,
    skip: &[&str],
) -> Result<(), String> {
    let Some(table) = known(pbrt_directive, plugin) else {
        return Err(format!(
            "line {}: {pbrt_directive} \"{plugin}\" is not one this checker knows (pbrt-v4 may; add it to the table)",
            st.line
        ));
    };
    for p in &st.params {
        if skip.contains(&p.name.as_str()) {
            continue;
        }
        let Some((_, allowed)) = table.iter().find(|(n, _)| *n == p.name) else {
            return Err(format!(
                "line {}: {pbrt_directive} \"{plugin}\" has no parameter `{}`",
                st.line, p.name
            ));
        };
        if !type_admits(allowed, &p.ty) {
            return Err(format!(
                "line {}: {pbrt_directive} \"{plugin}\" `{}` is {allowed}, not {}",
                st.line, p.name, p.ty
            ));
        }
    }
    Ok(())
}

/// What a checked scene holds, for the tests' own assertions.
pub struct Checked {
    pub statements: Vec<Statement>,
    /// Files named by the scene, resolved against its folder.
    pub files: Vec<std::path::PathBuf>,
}

impl Checked {
    pub fn first(&self, directive: &str) -> Option<&Statement> {
        self.statements.iter().find(|s| s.directive == directive)
    }
}

/// Reads and checks a pbrt-v4 scene file.
pub fn check_file(path: &Path) -> Result<Checked, String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let statements = parse(&text)?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let mut world = false;
    let mut depth = 0usize;
    let (mut materials, mut textures, mut media) =
        (BTreeSet::new(), BTreeSet::new(), BTreeSet::new());
    let mut counts: BTreeMap<&str, usize> = BTreeMap::new();
    let mut files = Vec::new();
    for st in &statements {
        let d = st.directive.as_str();
        *counts.entry(d).or_default() += 1;
        let at = st.line;
        if d == "WorldBegin" {
            if world {
                return Err(format!("line {at}: a second WorldBegin"));
            }
            world = true;
        }
        if OPTIONS.contains(&d) && world {
            return Err(format!("line {at}: {d} belongs before WorldBegin"));
        }
        if WORLD.contains(&d) && !world && d != "MediumInterface" {
            return Err(format!("line {at}: {d} belongs after WorldBegin"));
        }
        match d {
            "AttributeBegin" => depth += 1,
            "AttributeEnd" => {
                depth = depth
                    .checked_sub(1)
                    .ok_or_else(|| format!("line {at}: AttributeEnd without AttributeBegin"))?
            }
            "MakeNamedMaterial" => {
                let ty = st
                    .param("type")
                    .filter(|p| p.ty == "string")
                    .and_then(|p| p.values.first())
                    .ok_or_else(|| format!("line {at}: MakeNamedMaterial needs \"string type\""))?;
                check_plugin(st, "Material", ty, &["type"])?;
                if let Some(m) = st.param("materials") {
                    for name in &m.values {
                        if !materials.contains(name) {
                            return Err(format!("line {at}: material \"{name}\" is not made yet"));
                        }
                    }
                }
                materials.insert(st.args[0].clone());
            }
            "NamedMaterial" if !materials.contains(&st.args[0]) => {
                return Err(format!(
                    "line {at}: material \"{}\" is not made",
                    st.args[0]
                ));
            }
            "MakeNamedMedium" => {
                let ty = st
                    .param("type")
                    .and_then(|p| p.values.first())
                    .ok_or_else(|| format!("line {at}: MakeNamedMedium needs \"string type\""))?;
                check_plugin(st, "MakeNamedMedium", ty, &["type"])?;
                media.insert(st.args[0].clone());
            }
            "MediumInterface" => {
                for name in &st.args {
                    if !name.is_empty() && !media.contains(name) {
                        return Err(format!("line {at}: medium \"{name}\" is not made"));
                    }
                }
            }
            "Texture" => {
                if !matches!(st.args[1].as_str(), "spectrum" | "float") {
                    return Err(format!("line {at}: a texture is \"spectrum\" or \"float\""));
                }
                check_plugin(st, "Texture", &st.args[2], &[])?;
                textures.insert(st.args[0].clone());
            }
            "Camera" | "Sampler" | "Film" | "PixelFilter" | "Integrator" | "LightSource"
            | "Material" | "Shape" => check_plugin(st, d, &st.args[0], &[])?,
            _ => {}
        }
        for p in &st.params {
            if p.ty == "texture" {
                for name in &p.values {
                    if !textures.contains(name) {
                        return Err(format!("line {at}: texture \"{name}\" is not made"));
                    }
                }
            }
            // The film's file is pbrt's output; every other file must be there.
            if p.name == "filename" && d != "Film" {
                let f = dir.join(&p.values[0]);
                if !f.is_file() {
                    return Err(format!("line {at}: {} is not there", f.display()));
                }
                files.push(f);
            }
        }
    }
    if !world {
        return Err("no WorldBegin".into());
    }
    if depth != 0 {
        return Err(format!("{depth} AttributeBegin not ended"));
    }
    for one in ["Camera", "Film", "Sampler", "Integrator"] {
        if counts.get(one).copied().unwrap_or(0) > 1 {
            return Err(format!("{one} given more than once"));
        }
    }
    Ok(Checked { statements, files })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn misspelt_and_misplaced_statements_are_refused() {
        let ok = "LookAt 0 0 1 0 0 0 0 1 0\nCamera \"perspective\" \"float fov\" [ 40 ]\nWorldBegin\nAttributeBegin\nMaterial \"diffuse\" \"rgb reflectance\" [ 0.5 0.5 0.5 ]\nAttributeEnd\n";
        assert!(parse(ok).is_ok());
        let dir = tempfile::tempdir().unwrap();
        let write = |text: &str| {
            let p = dir.path().join("s.pbrt");
            std::fs::write(&p, text).unwrap();
            check_file(&p)
        };
        assert!(write(ok).is_ok());
        for (bad, why) in [
            (ok.replace("fov", "fob"), "no parameter `fob`"),
            (ok.replace("LookAt 0 0 1", "LookAt 0 0"), "takes 9 numbers"),
            (
                ok.replace("[ 0.5 0.5 0.5 ]", "[ 0.5 0.5 ]"),
                "three numbers",
            ),
            (ok.replace("AttributeEnd\n", ""), "not ended"),
            (format!("{ok}Camera \"perspective\"\n"), "before WorldBegin"),
            (
                ok.replace("\"float fov\" [ 40 ]", "\"float fov\" [ \"40\" ]"),
                "numbers expected",
            ),
            (
                ok.replace(
                    "Material \"diffuse\" \"rgb reflectance\" [ 0.5 0.5 0.5 ]",
                    "NamedMaterial \"skin\"",
                ),
                "not made",
            ),
        ] {
            let e = write(&bad).err().unwrap_or_default();
            assert!(e.contains(why), "{why}: {e}");
        }
    }
}
