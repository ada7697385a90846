//! xacro, the XML macro language most ROS robot descriptions are written in, expanded to
//! plain URDF. The semantics follow the reference implementation (ROS `xacro` 2.x, in
//! order, with lazy properties):
//!
//! - `xacro:property` (`value`, `default`, `remove`, `scope="parent|global"`,
//!   `lazy_eval`) and block properties (`<xacro:property name="b"><child/></xacro:property>`),
//! - `xacro:arg` with `default`, overridden by `NAME:=VALUE` given by the user,
//! - `${...}` Python expressions (arithmetic, comparisons, `x if c else y`, strings, `pi` and
//!   `math`'s functions, property references) and `$(arg)`, `$(find)`, `$(env)`,
//!   `$(optenv)`, `$(dirname)`, `$(cwd)`,
//! - `xacro:include` (relative, `$(find pkg)/...` or `package://pkg/...`, `optional`),
//! - `xacro:macro` with parameters, defaults (`p:=1`), forwarded defaults (`p:=^`,
//!   `p:=^|1`) and block parameters (`*origin`, `**content`), `xacro:insert_block`,
//!   `xacro:call`,
//! - `xacro:if` / `xacro:unless`, `xacro:element`, `xacro:attribute`.
//!
//! What it does not do is an error naming the file, the line and the construct:
//! namespaced includes (`ns=`), glob patterns in include names, `$(eval ...)`, and the
//! `xacro.` helpers in expressions (`xacro.load_yaml`). Comments are dropped, so
//! `xacro:eval-comments` has no effect.

pub(crate) mod dom;
mod expr;
mod packages;

pub use packages::{MAX_DEPTH, PackagePath};

use dom::{Element, Node, Pos};
use expr::{Segment, Value};
use pyisheval::Interpreter;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::rc::Rc;

/// What an expansion needs besides the file.
#[derive(Clone, Debug, Default)]
pub struct XacroOptions {
    /// `$(arg NAME)` values given by the user (`NAME:=VALUE`); they win over the defaults
    /// of `xacro:arg`.
    pub args: Vec<(String, String)>,
    /// Where `$(find pkg)` and `package://pkg` look.
    pub packages: PackagePath,
}

/// Reads a `NAME:=VALUE` argument (as `xacro` and `ros2 launch` take them).
pub fn parse_arg(s: &str) -> Option<(String, String)> {
    let (name, value) = s.split_once(":=")?;
    let name = name.trim();
    let valid = name.chars().next().is_some_and(|c| c.is_alphabetic() || c == '_')
        && name.chars().all(|c| c.is_alphanumeric() || c == '_');
    valid.then(|| (name.to_string(), value.to_string()))
}

/// Whether a robot description is xacro: its name ends in `.xacro`, or it declares or uses
/// the xacro namespace (TurtleBot3's `.urdf` files do).
pub fn is_xacro(file: &str, text: &str) -> bool {
    file.ends_with(".xacro") || text.contains("xmlns:xacro") || text.contains("<xacro:")
}

/// A finished expansion.
#[derive(Clone, Debug)]
pub struct Expansion {
    /// The URDF (or other XML) text.
    pub xml: String,
    /// Every file read, the top one first.
    pub files: Vec<PathBuf>,
    /// The value each `$(arg)` declared with `xacro:arg` or given by the user ended with.
    pub args: Vec<(String, String)>,
    /// Arguments the user gave that no `xacro:arg` declared and no `$(arg)` read.
    pub unused_args: Vec<String>,
}

/// A failed expansion: where, what, and through which includes and macro calls.
#[derive(Debug, thiserror::Error)]
#[error("{}{kind}{}", location(file, *line), trace_text(trace))]
pub struct XacroError {
    /// The file the offending construct is in.
    pub file: String,
    /// Its line (1-based; 0 when the whole file is meant).
    pub line: usize,
    /// What went wrong (boxed: errors travel up many frames and should stay small).
    pub kind: Box<XacroErrorKind>,
    /// The include and macro-call chain, innermost first.
    pub trace: Vec<String>,
}

fn location(file: &str, line: usize) -> String {
    if line == 0 { format!("{file}: ") } else { format!("{file}:{line}: ") }
}

fn trace_text(trace: &[String]) -> String {
    trace.iter().map(|t| format!("\n  {t}")).collect()
}

/// What went wrong in an expansion.
#[derive(Debug, thiserror::Error)]
pub enum XacroErrorKind {
    /// A file could not be read.
    #[error("cannot read `{path}`: {error}")]
    Io {
        /// The file.
        path: String,
        /// What the OS said.
        error: std::io::Error,
    },
    /// Not well-formed XML.
    #[error("not well-formed XML: {0}")]
    Xml(String),
    /// A xacro construct rlnav does not expand.
    #[error("{0} is not supported by rlnav's xacro (expand the file with ROS's `xacro` first)")]
    Unsupported(String),
    /// A directive lacks an attribute it needs.
    #[error("<{element}> needs the attribute `{attribute}`")]
    MissingAttribute {
        /// The directive, e.g. `xacro:property`.
        element: String,
        /// The attribute.
        attribute: String,
    },
    /// A `${...}` expression failed.
    #[error("cannot evaluate `${{{expr}}}`: {message}")]
    Expression {
        /// The expression.
        expr: String,
        /// Why.
        message: String,
    },
    /// `$(arg NAME)` of an argument nobody declared or gave.
    #[error(
        "`$(arg {0})` is not defined: declare it with <xacro:arg name=\"{0}\" default=\"...\"/> or give {0}:=VALUE"
    )]
    UndefinedArg(String),
    /// `$(find PKG)` or `package://PKG` of a package not on the search path.
    #[error("package `{name}` not found (give its folder with --package-path); searched {searched}")]
    PackageNotFound {
        /// The package.
        name: String,
        /// Where it was looked for.
        searched: String,
    },
    /// `$(env NAME)` of an unset variable.
    #[error("`$(env {0})`: environment variable `{0}` is not set")]
    EnvNotSet(String),
    /// An `xacro:if`/`unless` condition that is not a boolean.
    #[error("<{directive} value=\"{condition}\"> evaluated to `{value}`, which is not a boolean (true, false, 1, 0)")]
    NotBoolean {
        /// `xacro:if` or `xacro:unless`.
        directive: String,
        /// The condition as written.
        condition: String,
        /// What it evaluated to.
        value: String,
    },
    /// A `<xacro:NAME>` that is no directive and no macro defined so far.
    #[error("unknown macro `xacro:{0}` (not defined before this point, or defined in a macro that has ended)")]
    UnknownMacro(String),
    /// A macro called with the wrong parameters or blocks.
    #[error("macro `{name}`: {message}")]
    MacroCall {
        /// The macro.
        name: String,
        /// What is wrong.
        message: String,
    },
    /// Anything else the file gets wrong (bad names, unknown substitutions).
    #[error("{0}")]
    Invalid(String),
}

/// Expands a xacro file.
pub fn expand_file(path: &Path, options: &XacroOptions) -> Result<Expansion, XacroError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path).map_err(|error| XacroError {
        file: file.clone(),
        line: 0,
        kind: Box::new(XacroErrorKind::Io { path: file.clone(), error }),
        trace: Vec::new(),
    })?;
    expand_str(&file, &text, options)
}

/// Expands xacro text; `file` names it in messages, and relative includes are relative to
/// its folder.
pub fn expand_str(file: &str, text: &str, options: &XacroOptions) -> Result<Expansion, XacroError> {
    let mut x = Expander::new(options);
    let path = PathBuf::from(file);
    let root = x.parse(&path, text, None)?;
    x.files.push(path.clone());
    x.read.push(path);
    let top = x.new_scope(None);
    let mut out = x.expand_element(&root, top)?;
    if let Some(ns) = root.attr("xacro:targetNamespace") {
        out.set_attr("xmlns", ns.to_string());
    }
    let mut args: Vec<(String, String)> = x.args.iter().map(|(k, v)| (k.clone(), v.clone())).collect();
    args.sort();
    let mut unused_args: Vec<String> =
        options.args.iter().map(|(k, _)| k.clone()).filter(|k| !x.used_args.contains(k)).collect();
    unused_args.dedup();
    Ok(Expansion { xml: dom::write(&out), files: x.read, args, unused_args })
}

/// How deep macros may call macros (a macro calling itself without end stops here).
const MAX_MACRO_DEPTH: usize = 200;

/// A macro parameter as declared: `name`, `name:=default`, `name:=^|default`, `*block`.
#[derive(Clone, Debug, PartialEq)]
struct Param {
    name: String,
    /// `^`: take the caller's property of the same name when it has one.
    forward: bool,
    default: Option<String>,
}

#[derive(Debug)]
struct Macro {
    params: Vec<Param>,
    body: Element,
}

/// A property's state; properties are evaluated when first used.
#[derive(Clone, Debug)]
enum Slot {
    Lazy(String),
    Evaluating,
    Ready(Value),
    /// A block: a macro's block parameter or a block property; `content` inserts its
    /// children only.
    Block {
        element: Rc<Element>,
        content: bool,
    },
}

#[derive(Debug)]
struct Property {
    slot: Slot,
    pos: Pos,
}

/// A symbol table: each macro call opens one whose parent is the caller's (xacro scopes
/// dynamically).
#[derive(Debug, Default)]
struct Scope {
    parent: Option<usize>,
    vars: HashMap<String, Property>,
    macros: HashMap<String, Rc<Macro>>,
}

/// An attribute an expansion sets on the element around it.
enum ParentAttr {
    /// `xacro:attribute`: set, replacing.
    Set(String, String),
    /// An `xmlns:` declaration of an included file or macro: set when absent.
    Namespace(String, String),
}

struct Expander<'o> {
    options: &'o XacroOptions,
    args: HashMap<String, String>,
    used_args: Vec<String>,
    interp: Rc<Interpreter>,
    scopes: Vec<Scope>,
    /// The files being expanded, innermost last (relative includes start from the last).
    files: Vec<PathBuf>,
    /// Every file read, in order.
    read: Vec<PathBuf>,
    parsed: HashMap<PathBuf, Rc<Element>>,
    packages: HashMap<String, Option<PathBuf>>,
    trace: Vec<String>,
    depth: usize,
}

fn at(pos: &Pos) -> String {
    format!("{}:{}", pos.file, pos.line)
}

fn is_identifier(s: &str) -> bool {
    const KEYWORDS: &[&str] = &[
        "False", "None", "True", "and", "as", "assert", "async", "await", "break", "class", "continue", "def", "del",
        "elif", "else", "except", "finally", "for", "from", "global", "if", "import", "in", "is", "lambda", "nonlocal",
        "not", "or", "pass", "raise", "return", "try", "while", "with", "yield",
    ];
    s.chars().next().is_some_and(|c| c.is_alphabetic() || c == '_')
        && s.chars().all(|c| c.is_alphanumeric() || c == '_')
        && !KEYWORDS.contains(&s)
}

/// A string value, literal-typed as xacro's property table types it; other values as they are.
fn literalize(v: Value) -> Value {
    match v {
        Value::Str(s) => Value::literal(s),
        other => other,
    }
}

/// Splits a macro's `params` as xacro's `parse_macro_arg` does.
fn parse_params(spec: &str) -> Vec<Param> {
    let mut out = Vec::new();
    let mut rest = spec.trim_start();
    while !rest.is_empty() {
        let name_end = rest.find(|c: char| c.is_whitespace() || c == ':' || c == '=').unwrap_or(rest.len());
        let name = &rest[..name_end];
        let after = rest[name_end..].trim_start();
        let spec_start = if after.starts_with(":=") {
            Some(2)
        } else if after.starts_with('=') {
            Some(1)
        } else {
            None
        };
        let Some(skip) = spec_start.filter(|_| !name.is_empty()) else {
            // No default: the name runs to the next space.
            let end = rest.find(char::is_whitespace).unwrap_or(rest.len());
            out.push(Param { name: rest[..end].to_string(), forward: false, default: None });
            rest = rest[end..].trim_start();
            continue;
        };
        let mut value = after[skip..].trim_start();
        let forward = value.starts_with('^');
        if forward {
            value = value.strip_prefix("^|").unwrap_or(&value[1..]);
        }
        // The default runs to the next space outside quotes, `${...}` and `$(...)`.
        let b = value.as_bytes();
        let mut i = 0;
        while i < b.len() && !b[i].is_ascii_whitespace() {
            let close = match b[i] {
                b'$' if i + 1 < b.len() && b[i + 1] == b'{' => Some(b'}'),
                b'$' if i + 1 < b.len() && b[i + 1] == b'(' => Some(b')'),
                q @ (b'\'' | b'"') => Some(q),
                _ => None,
            };
            i = match close {
                Some(c) => {
                    let from = if b[i] == b'$' { i + 2 } else { i + 1 };
                    value[from..].find(c as char).map_or(b.len(), |j| from + j + 1)
                }
                None => i + 1,
            };
        }
        let default = &value[..i];
        out.push(Param {
            name: name.to_string(),
            forward,
            default: (!default.is_empty()).then(|| default.to_string()),
        });
        rest = value[i..].trim_start();
    }
    out
}

impl<'o> Expander<'o> {
    fn new(options: &'o XacroOptions) -> Self {
        Self {
            options,
            args: options.args.iter().cloned().collect(),
            used_args: Vec::new(),
            interp: Rc::new(Interpreter::new()),
            scopes: Vec::new(),
            files: Vec::new(),
            read: Vec::new(),
            parsed: HashMap::new(),
            packages: HashMap::new(),
            trace: Vec::new(),
            depth: 0,
        }
    }

    fn err(&self, pos: &Pos, kind: XacroErrorKind) -> XacroError {
        XacroError {
            file: pos.file.to_string(),
            line: pos.line,
            kind: Box::new(kind),
            trace: self.trace.iter().rev().cloned().collect(),
        }
    }

    fn parse(&mut self, path: &Path, text: &str, from: Option<&Pos>) -> Result<Rc<Element>, XacroError> {
        if let Some(root) = self.parsed.get(path) {
            return Ok(root.clone());
        }
        let file: Rc<str> = Rc::from(path.display().to_string());
        let root = dom::parse(&file, text).map_err(|e| {
            let mut err = self.err(&Pos { file: file.clone(), line: e.line }, XacroErrorKind::Xml(e.message));
            if let Some(p) = from {
                err.trace.insert(0, format!("included at {}", at(p)));
            }
            err
        })?;
        let root = Rc::new(root);
        self.parsed.insert(path.to_path_buf(), root.clone());
        Ok(root)
    }

    fn new_scope(&mut self, parent: Option<usize>) -> usize {
        self.scopes.push(Scope { parent, ..Scope::default() });
        self.scopes.len() - 1
    }

    /// The scope (this one or an ancestor) that defines `key`.
    fn scope_of(&self, mut scope: usize, key: &str) -> Option<usize> {
        loop {
            if self.scopes[scope].vars.contains_key(key) {
                return Some(scope);
            }
            scope = self.scopes[scope].parent?;
        }
    }

    fn find_macro(&self, mut scope: usize, name: &str) -> Option<Rc<Macro>> {
        loop {
            if let Some(m) = self.scopes[scope].macros.get(name) {
                return Some(m.clone());
            }
            scope = self.scopes[scope].parent?;
        }
    }

    fn set_var(&mut self, scope: usize, key: String, slot: Slot, pos: &Pos) {
        self.scopes[scope].vars.insert(key, Property { slot, pos: pos.clone() });
    }

    /// A property's value, evaluating it on first use; `None` when nothing defines it.
    fn get_var(&mut self, scope: usize, name: &str, used_at: &Pos) -> Result<Option<Value>, XacroError> {
        let Some(owner) = self.scope_of(scope, name) else { return Ok(None) };
        let prop = &self.scopes[owner].vars[name];
        let def = prop.pos.clone();
        match prop.slot.clone() {
            Slot::Ready(v) => Ok(Some(v)),
            Slot::Block { .. } => Ok(None),
            Slot::Evaluating => Err(self.err(
                &def,
                XacroErrorKind::Invalid(format!("circular property definition: `{name}` depends on itself")),
            )),
            Slot::Lazy(text) => {
                self.scopes[owner].vars.get_mut(name).expect("found above").slot = Slot::Evaluating;
                self.trace.push(format!("evaluating property `{name}` (used at {})", at(used_at)));
                // A lazy property is evaluated in the scope that defined it.
                let result = self.eval_text(&text, owner, &def);
                self.trace.pop();
                let prop = self.scopes[owner].vars.get_mut(name).expect("found above");
                match result {
                    Ok(v) => {
                        let v = literalize(v);
                        prop.slot = Slot::Ready(v.clone());
                        Ok(Some(v))
                    }
                    Err(e) => {
                        prop.slot = Slot::Lazy(text);
                        Err(e)
                    }
                }
            }
        }
    }

    /// Evaluates attribute or text content: typed when it is a single `${}`/`$()`, else the
    /// pieces joined as text.
    fn eval_text(&mut self, text: &str, scope: usize, pos: &Pos) -> Result<Value, XacroError> {
        if !text.contains('$') {
            return Ok(Value::Str(text.to_string()));
        }
        let segs = expr::segments(text).map_err(|m| self.err(pos, XacroErrorKind::Invalid(m)))?;
        let mut values = Vec::with_capacity(segs.len());
        for seg in segs {
            values.push(match seg {
                Segment::Text(t) => Value::Str(t.to_string()),
                Segment::Expr(e) => {
                    let code = self.eval_text(e, scope, pos)?.to_text();
                    let interp = self.interp.clone();
                    let mut lookup_err = None;
                    let result = expr::eval_python(&interp, &code, &mut |name| match self.get_var(scope, name, pos) {
                        Ok(v) => Ok(v),
                        Err(e) => {
                            lookup_err = Some(e);
                            Err(String::new())
                        }
                    });
                    if let Some(e) = lookup_err {
                        return Err(e);
                    }
                    result
                        .map_err(|message| self.err(pos, XacroErrorKind::Expression { expr: e.to_string(), message }))?
                }
                Segment::Subst(s) => {
                    let inner = self.eval_text(s, scope, pos)?.to_text();
                    Value::Str(self.substitute(&inner, pos)?)
                }
            });
        }
        if values.len() == 1 {
            return Ok(values.pop().expect("one value"));
        }
        Ok(Value::Str(values.iter().map(Value::to_text).collect()))
    }

    /// `$(command args)`.
    fn substitute(&mut self, inner: &str, pos: &Pos) -> Result<String, XacroError> {
        let words: Vec<&str> = inner.split_whitespace().collect();
        let one = |this: &Self| match words.as_slice() {
            [_, a] => Ok(a.to_string()),
            _ => Err(this.err(pos, XacroErrorKind::Invalid(format!("`$({inner})` takes exactly one argument")))),
        };
        match words.first().copied() {
            Some("arg") => {
                let name = one(self)?;
                if !self.used_args.contains(&name) {
                    self.used_args.push(name.clone());
                }
                self.args.get(&name).cloned().ok_or_else(|| self.err(pos, XacroErrorKind::UndefinedArg(name)))
            }
            Some("find") => {
                let name = one(self)?;
                self.package(&name, pos).map(|p| p.display().to_string())
            }
            Some("env") => {
                let name = one(self)?;
                std::env::var(&name).map_err(|_| self.err(pos, XacroErrorKind::EnvNotSet(name)))
            }
            Some("optenv") if words.len() >= 2 => Ok(std::env::var(words[1]).unwrap_or_else(|_| words[2..].join(" "))),
            Some("dirname") => {
                let file = self.files.last().cloned().unwrap_or_default();
                let dir = file.parent().map(Path::to_path_buf).unwrap_or_default();
                Ok(std::path::absolute(&dir).unwrap_or(dir).display().to_string())
            }
            Some("cwd") => Ok(std::env::current_dir().map(|d| d.display().to_string()).unwrap_or_else(|_| ".".into())),
            Some("eval") => Err(self.err(pos, XacroErrorKind::Unsupported(format!("`$({inner})`")))),
            _ => Err(self.err(
                pos,
                XacroErrorKind::Invalid(format!(
                    "unknown substitution `$({inner})` (known: arg, find, env, optenv, dirname, cwd)"
                )),
            )),
        }
    }

    fn package(&mut self, name: &str, pos: &Pos) -> Result<PathBuf, XacroError> {
        let options = self.options;
        let found = self.packages.entry(name.to_string()).or_insert_with(|| options.packages.find(name)).clone();
        found.ok_or_else(|| {
            self.err(
                pos,
                XacroErrorKind::PackageNotFound { name: name.to_string(), searched: self.options.packages.describe() },
            )
        })
    }

    fn required<'e>(&self, el: &'e Element, attribute: &str) -> Result<&'e str, XacroError> {
        el.attr(attribute).ok_or_else(|| {
            self.err(
                &el.pos,
                XacroErrorKind::MissingAttribute { element: el.name.clone(), attribute: attribute.into() },
            )
        })
    }

    fn condition(&mut self, el: &Element, text: &str, scope: usize) -> Result<bool, XacroError> {
        let v = self.eval_text(text, scope, &el.pos)?;
        v.condition().ok_or_else(|| {
            self.err(
                &el.pos,
                XacroErrorKind::NotBoolean { directive: el.name.clone(), condition: text.into(), value: v.to_text() },
            )
        })
    }

    /// An element with its attributes evaluated and its children expanded.
    fn expand_element(&mut self, el: &Element, scope: usize) -> Result<Element, XacroError> {
        let mut out = Element { name: el.name.clone(), attrs: Vec::new(), children: Vec::new(), pos: el.pos.clone() };
        for (k, v) in &el.attrs {
            if k.starts_with("xacro:") || k == "xmlns:xacro" {
                continue;
            }
            let v = self.eval_text(v, scope, &el.pos)?.to_text();
            out.attrs.push((k.clone(), v));
        }
        let mut set = Vec::new();
        out.children = self.expand_nodes(&el.children, scope, &el.pos, &mut set)?;
        for attr in set {
            match attr {
                ParentAttr::Set(k, v) => out.set_attr(&k, v),
                ParentAttr::Namespace(k, v) => {
                    if out.attr(&k).is_none() {
                        out.attrs.push((k, v));
                    }
                }
            }
        }
        Ok(out)
    }

    fn expand_nodes(
        &mut self,
        nodes: &[Node],
        scope: usize,
        parent: &Pos,
        parent_attrs: &mut Vec<ParentAttr>,
    ) -> Result<Vec<Node>, XacroError> {
        let mut out = Vec::with_capacity(nodes.len());
        for node in nodes {
            match node {
                Node::Element(e) => self.expand_into(e, scope, &mut out, parent_attrs)?,
                Node::Text(t, line) => {
                    let pos = Pos { file: parent.file.clone(), line: if *line > 0 { *line } else { parent.line } };
                    out.push(Node::Text(self.eval_text(t, scope, &pos)?.to_text(), 0));
                }
                Node::CData(c) => out.push(Node::CData(c.clone())),
            }
        }
        Ok(out)
    }

    /// Expands one element into `out`: a directive, a macro call or a plain element.
    fn expand_into(
        &mut self,
        el: &Element,
        scope: usize,
        out: &mut Vec<Node>,
        parent_attrs: &mut Vec<ParentAttr>,
    ) -> Result<(), XacroError> {
        let Some(directive) = el.name.strip_prefix("xacro:") else {
            out.push(Node::Element(self.expand_element(el, scope)?));
            return Ok(());
        };
        match directive {
            "property" => self.define_property(el, scope),
            "macro" => self.define_macro(el, scope),
            "arg" => {
                let name = self.required(el, "name")?;
                let default = self.required(el, "default")?;
                if !self.args.contains_key(name) {
                    let v = self.eval_text(default, scope, &el.pos)?.to_text();
                    self.args.insert(name.to_string(), v);
                }
                if !self.used_args.iter().any(|a| a == name) {
                    self.used_args.push(name.to_string());
                }
                Ok(())
            }
            "include" => self.include(el, scope, out, parent_attrs),
            "if" | "unless" => {
                let cond = self.required(el, "value")?;
                let keep = self.condition(el, cond, scope)? == (directive == "if");
                if keep {
                    // As in xacro, what the body sets on its parent is set on the discarded
                    // `xacro:if` element.
                    let mut lost = Vec::new();
                    out.extend(self.expand_nodes(&el.children, scope, &el.pos, &mut lost)?);
                }
                Ok(())
            }
            "insert_block" => {
                let name = self.required(el, "name")?;
                let found = [format!("**{name}"), format!("*{name}")].into_iter().find_map(|key| {
                    let owner = self.scope_of(scope, &key)?;
                    match &self.scopes[owner].vars[&key].slot {
                        Slot::Block { element, content } => Some((element.clone(), *content)),
                        _ => None,
                    }
                });
                let (block, content) = found
                    .ok_or_else(|| self.err(&el.pos, XacroErrorKind::Invalid(format!("undefined block `{name}`"))))?;
                let expanded = self.expand_element(&block, scope)?;
                if content {
                    out.extend(expanded.children);
                } else {
                    out.push(Node::Element(expanded));
                }
                Ok(())
            }
            "element" => {
                let name = self.required(el, "xacro:name")?;
                let name = self.eval_text(name, scope, &el.pos)?.to_text();
                if name.is_empty() {
                    return Err(self.err(&el.pos, XacroErrorKind::Invalid("xacro:element: empty name".into())));
                }
                let mut renamed = el.clone();
                renamed.name = name;
                renamed.attrs.retain(|(k, _)| k != "xacro:name");
                self.expand_into(&renamed, scope, out, parent_attrs)
            }
            "attribute" => {
                let (name, value) = (self.required(el, "name")?, self.required(el, "value")?);
                let name = self.eval_text(name, scope, &el.pos)?.to_text();
                let value = self.eval_text(value, scope, &el.pos)?.to_text();
                if name.is_empty() {
                    return Err(self.err(&el.pos, XacroErrorKind::Invalid("xacro:attribute: empty name".into())));
                }
                parent_attrs.push(ParentAttr::Set(name, value));
                Ok(())
            }
            _ => self.call_macro(el, scope, out, parent_attrs),
        }
    }

    fn define_property(&mut self, el: &Element, scope: usize) -> Result<(), XacroError> {
        let invalid = |this: &Self, m: String| this.err(&el.pos, XacroErrorKind::Invalid(m));
        if let Some((k, _)) = el.attrs.iter().find(|(k, _)| {
            !["name", "value", "default", "remove", "scope", "lazy_eval"].contains(&k.as_str())
                && !k.starts_with("xmlns:")
        }) {
            return Err(invalid(self, format!("<xacro:property> has an unknown attribute `{k}`")));
        }
        let name = self.required(el, "name")?;
        let name = self.eval_text(name, scope, &el.pos)?.to_text();
        if !is_identifier(&name) || name.starts_with("__") {
            return Err(invalid(self, format!("property name `{name}` is not a valid Python identifier")));
        }
        let remove = match el.attr("remove") {
            Some(r) => self.condition(el, r, scope)?,
            None => false,
        };
        let (value, default) = (el.attr("value"), el.attr("default"));
        if usize::from(value.is_some()) + usize::from(default.is_some()) + usize::from(remove) > 1 {
            return Err(invalid(
                self,
                format!("property `{name}`: `value`, `default` and `remove` exclude each other"),
            ));
        }
        if remove {
            let mut s = Some(scope);
            while let Some(i) = s {
                self.scopes[i].vars.remove(&name);
                s = self.scopes[i].parent;
            }
            return Ok(());
        }
        let value = match default {
            Some(_) if self.scope_of(scope, &name).is_some() => return Ok(()),
            Some(d) => Some(d),
            None => value,
        };
        let mut lazy = match el.attr("lazy_eval") {
            Some(l) => self.condition(el, l, scope)?,
            None => true,
        };
        let target = match el.attr("scope") {
            Some("global") => {
                lazy = false;
                0
            }
            Some("parent") => {
                lazy = false;
                match self.scopes[scope].parent {
                    Some(p) => p,
                    // As xacro: there is nowhere to put it.
                    None => return Ok(()),
                }
            }
            _ => scope,
        };
        let Some(value) = value else {
            let block = Rc::new(el.clone());
            self.set_var(target, format!("**{name}"), Slot::Block { element: block, content: true }, &el.pos);
            return Ok(());
        };
        let slot = if lazy {
            match Value::literal(value.to_string()) {
                Value::Str(s) => Slot::Lazy(s),
                v => Slot::Ready(v),
            }
        } else {
            Slot::Ready(literalize(self.eval_text(value, scope, &el.pos)?))
        };
        self.set_var(target, name, slot, &el.pos);
        Ok(())
    }

    fn define_macro(&mut self, el: &Element, scope: usize) -> Result<(), XacroError> {
        let name = self.required(el, "name")?;
        let name = name.strip_prefix("xacro:").unwrap_or(name);
        if name == "call" || name.contains('.') || name.is_empty() {
            return Err(self.err(&el.pos, XacroErrorKind::Invalid(format!("invalid macro name `{name}`"))));
        }
        let params = parse_params(el.attr("params").unwrap_or(""));
        for p in &params {
            let bare = p.name.trim_start_matches('*');
            if !is_identifier(bare) || p.name.len() - bare.len() > 2 {
                return Err(self
                    .err(&el.pos, XacroErrorKind::Invalid(format!("macro `{name}`: invalid parameter `{}`", p.name))));
            }
        }
        let m = Macro { params, body: el.clone() };
        self.scopes[scope].macros.insert(name.to_string(), Rc::new(m));
        Ok(())
    }

    fn call_macro(
        &mut self,
        el: &Element,
        scope: usize,
        out: &mut Vec<Node>,
        parent_attrs: &mut Vec<ParentAttr>,
    ) -> Result<(), XacroError> {
        let (name, attrs): (String, Vec<&(String, String)>) = if el.name == "xacro:call" {
            let m = self.required(el, "macro")?;
            let name = self.eval_text(m, scope, &el.pos)?.to_text();
            (name, el.attrs.iter().filter(|(k, _)| k != "macro").collect())
        } else {
            (el.name["xacro:".len()..].to_string(), el.attrs.iter().collect())
        };
        let Some(m) = self.find_macro(scope, &name) else {
            return Err(if name.contains('.') {
                self.err(&el.pos, XacroErrorKind::Unsupported(format!("the namespaced macro call `xacro:{name}`")))
            } else {
                self.err(&el.pos, XacroErrorKind::UnknownMacro(name))
            });
        };
        if self.depth >= MAX_MACRO_DEPTH {
            return Err(self.err(
                &el.pos,
                XacroErrorKind::MacroCall {
                    name,
                    message: format!(
                        "macros nest deeper than {MAX_MACRO_DEPTH} (a macro that calls itself without end?)"
                    ),
                },
            ));
        }
        let call_err =
            |this: &Self, message: String| this.err(&el.pos, XacroErrorKind::MacroCall { name: name.clone(), message });
        let local = self.new_scope(Some(scope));
        let mut pending: Vec<&Param> = m.params.iter().collect();
        for (k, v) in attrs {
            let Some(i) = pending.iter().position(|p| p.name == *k) else {
                let known: Vec<&str> = m.params.iter().map(|p| p.name.as_str()).collect();
                return Err(call_err(self, format!("unknown parameter `{k}` (parameters: {})", known.join(" "))));
            };
            pending.remove(i);
            let v = literalize(self.eval_text(v, scope, &el.pos)?);
            self.set_var(local, k.clone(), Slot::Ready(v), &el.pos);
        }
        // Block parameters take the call's child elements in order, expanded where the call is.
        let mut lost = Vec::new();
        let children = self.expand_nodes(&el.children, scope, &el.pos, &mut lost)?;
        let mut blocks = children.into_iter().filter_map(|n| match n {
            Node::Element(e) => Some(e),
            _ => None,
        });
        for p in m.params.iter().filter(|p| p.name.starts_with('*')) {
            let Some(block) = blocks.next() else {
                return Err(call_err(self, format!("not enough blocks: no element for `{}`", p.name)));
            };
            let content = p.name.starts_with("**");
            self.set_var(local, p.name.clone(), Slot::Block { element: Rc::new(block), content }, &el.pos);
        }
        pending.retain(|p| !p.name.starts_with('*'));
        if let Some(extra) = blocks.next() {
            return Err(call_err(self, format!("unused block <{}>", extra.name)));
        }
        let mut missing = Vec::new();
        for p in pending {
            let forwarded = if p.forward { self.get_var(scope, &p.name, &el.pos)? } else { None };
            let v = match (forwarded, &p.default) {
                (Some(v), _) => v,
                (None, Some(d)) => literalize(self.eval_text(d, scope, &el.pos)?),
                (None, None) if p.forward => {
                    return Err(call_err(self, format!("no property `{}` to forward (`{}:=^`)", p.name, p.name)));
                }
                (None, None) => {
                    missing.push(p.name.as_str());
                    continue;
                }
            };
            self.set_var(local, p.name.clone(), Slot::Ready(v), &el.pos);
        }
        if !missing.is_empty() {
            return Err(call_err(self, format!("missing parameters: {}", missing.join(", "))));
        }
        self.trace.push(format!("in macro `{name}` called at {}", at(&el.pos)));
        self.depth += 1;
        let mut lost = Vec::new();
        let body = self.expand_nodes(&m.body.children, local, &m.body.pos, &mut lost);
        self.depth -= 1;
        self.trace.pop();
        out.extend(body?);
        for (k, v) in &m.body.attrs {
            if k.starts_with("xmlns:") && k != "xmlns:xacro" {
                parent_attrs.push(ParentAttr::Namespace(k.clone(), v.clone()));
            }
        }
        Ok(())
    }

    fn include(
        &mut self,
        el: &Element,
        scope: usize,
        out: &mut Vec<Node>,
        parent_attrs: &mut Vec<ParentAttr>,
    ) -> Result<(), XacroError> {
        if el.attr("ns").is_some() {
            return Err(self
                .err(&el.pos, XacroErrorKind::Unsupported("<xacro:include ns=\"...\"> (namespaced include)".into())));
        }
        let spec = self.required(el, "filename")?;
        let spec = self.eval_text(spec, scope, &el.pos)?.to_text();
        if spec.contains(['*', '?', '[']) {
            return Err(self.err(
                &el.pos,
                XacroErrorKind::Unsupported(format!("the glob pattern in <xacro:include filename=\"{spec}\">")),
            ));
        }
        let optional = el.attr("optional").is_some_and(|o| Value::literal(o.to_string()).condition() == Some(true));
        let path = match spec.strip_prefix("package://") {
            Some(rest) => {
                let (pkg, file) = rest.split_once('/').unwrap_or((rest, ""));
                self.package(pkg, &el.pos)?.join(file)
            }
            None if Path::new(&spec).is_relative() => {
                let base = self.files.last().and_then(|f| f.parent()).map(Path::to_path_buf).unwrap_or_default();
                base.join(&spec)
            }
            None => PathBuf::from(&spec),
        };
        if self.files.contains(&path) {
            return Err(self.err(
                &el.pos,
                XacroErrorKind::Invalid(format!("`{}` includes itself (include cycle)", path.display())),
            ));
        }
        let root = match self.parsed.get(&path) {
            Some(r) => r.clone(),
            None => match std::fs::read_to_string(&path) {
                Ok(text) => self.parse(&path, &text, Some(&el.pos))?,
                Err(_) if optional => return Ok(()),
                Err(error) => {
                    return Err(self.err(&el.pos, XacroErrorKind::Io { path: path.display().to_string(), error }));
                }
            },
        };
        if !self.read.contains(&path) {
            self.read.push(path.clone());
        }
        self.files.push(path.clone());
        self.trace.push(format!("in {} included at {}", path.display(), at(&el.pos)));
        let mut lost = Vec::new();
        let body = self.expand_nodes(&root.children, scope, &root.pos, &mut lost);
        self.trace.pop();
        self.files.pop();
        out.extend(body?);
        for (k, v) in &root.attrs {
            if k.starts_with("xmlns:") && k != "xmlns:xacro" {
                parent_attrs.push(ParentAttr::Namespace(k.clone(), v.clone()));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn expand(text: &str) -> Result<String, XacroError> {
        expand_str("mem.xacro", text, &XacroOptions::default()).map(|e| e.xml)
    }

    fn robot(body: &str) -> String {
        format!("<robot name=\"r\" xmlns:xacro=\"http://ros.org/wiki/xacro\">{body}</robot>")
    }

    #[test]
    fn macro_parameters_parse_like_xacros() {
        let p = parse_params("name parent:=base_link  r:=${3*cm2m} s:='a b' *origin f:=^ g:=^|0.5 **body v:=$(arg x)");
        let show: Vec<(String, bool, Option<String>)> = p.into_iter().map(|p| (p.name, p.forward, p.default)).collect();
        let o = |s: &str| Some(s.to_string());
        assert_eq!(
            show,
            vec![
                ("name".into(), false, None),
                ("parent".into(), false, o("base_link")),
                ("r".into(), false, o("${3*cm2m}")),
                ("s".into(), false, o("'a b'")),
                ("*origin".into(), false, None),
                ("f".into(), true, None),
                ("g".into(), true, o("0.5")),
                ("**body".into(), false, None),
                ("v".into(), false, o("$(arg x)")),
            ]
        );
    }

    #[test]
    fn properties_are_lazy_scoped_and_typed() {
        let out = expand(&robot(
            "<xacro:property name=\"b\" value=\"${a*2}\"/><xacro:property name=\"a\" value=\"1.25\"/>\
             <link name=\"l${b}\"/>\
             <xacro:property name=\"a\" default=\"9\"/><xacro:property name=\"c\" default=\"4\"/>\
             <x v=\"${a} ${c} ${c/8} ${'s' + 'x'} $${kept}\"/>",
        ))
        .unwrap();
        assert!(out.contains("<link name=\"l2.5\"/>"), "{out}");
        assert!(out.contains("<x v=\"1.25 4 0.5 sx ${kept}\"/>"), "{out}");
        assert!(!out.contains("xacro"), "{out}");
    }

    #[test]
    fn macros_blocks_defaults_and_conditionals() {
        let out = expand(&robot(
            "<xacro:property name=\"side\" value=\"left\"/>\
             <xacro:property name=\"mat\"><material name=\"m\"/></xacro:property>\
             <xacro:macro name=\"wheel\" params=\"name r:=0.1 side:=^ *origin **extra\">\
               <joint name=\"${name}_joint\"><xacro:insert_block name=\"origin\"/></joint>\
               <link name=\"${name}_${side}\" r=\"${r}\"><xacro:insert_block name=\"extra\"/><xacro:insert_block name=\"mat\"/></link>\
               <xacro:if value=\"${r &gt; 0.05}\"><big/></xacro:if><xacro:unless value=\"false\"><always/></xacro:unless>\
             </xacro:macro>\
             <xacro:wheel name=\"w\" r=\"0.03\"><origin xyz=\"0 ${0.1/2} 0\"/><extra><a/><b/></extra></xacro:wheel>\
             <xacro:call macro=\"wheel\" name=\"v\"><origin/><e/></xacro:call>",
        ))
        .unwrap();
        assert!(out.contains("<joint name=\"w_joint\"><origin xyz=\"0 0.05 0\"/></joint>"), "{out}");
        assert!(
            out.contains("<link name=\"w_left\" r=\"0.03\"><a/><b/><material name=\"m\"/></link><always/>"),
            "{out}"
        );
        assert!(out.contains("<link name=\"v_left\" r=\"0.1\"><material name=\"m\"/></link><big/><always/>"), "{out}");
    }

    #[test]
    fn args_and_dynamic_elements() {
        let text = robot(
            "<xacro:arg name=\"ns\" default=\"\"/><xacro:arg name=\"use_x\" default=\"true\"/>\
             <link name=\"$(arg ns)base\"/>\
             <xacro:if value=\"$(arg use_x)\"><xacro:element xacro:name=\"x_${1+1}\" k=\"v\"><xacro:attribute name=\"q\" value=\"${2*2}\"/></xacro:element></xacro:if>",
        );
        let out = expand(&text).unwrap();
        assert!(out.contains("<link name=\"base\"/><x_2 k=\"v\" q=\"4\"/>"), "{out}");
        let given = XacroOptions {
            args: vec![("ns".into(), "tb3_".into()), ("nope".into(), "1".into())],
            ..Default::default()
        };
        let e = expand_str("mem.xacro", &text, &given).unwrap();
        assert!(e.xml.contains("<link name=\"tb3_base\"/>"), "{}", e.xml);
        assert_eq!(e.unused_args, vec!["nope".to_string()]);
        assert!(e.args.contains(&("use_x".into(), "true".into())));
        assert_eq!(parse_arg("ns:=tb3_"), Some(("ns".into(), "tb3_".into())));
        assert_eq!(parse_arg("a:=b:=c"), Some(("a".into(), "b:=c".into())));
        assert_eq!(parse_arg("no_value"), None);
        assert_eq!(parse_arg("1x:=2"), None);
    }

    #[test]
    fn errors_name_the_file_line_and_construct() {
        let e = expand(&robot("\n\n<link name=\"${undefined_prop * 2}\"/>")).unwrap_err();
        assert_eq!((e.file.as_str(), e.line), ("mem.xacro", 3));
        assert!(e.to_string().starts_with("mem.xacro:3: cannot evaluate `${undefined_prop * 2}`"), "{e}");
        let e = expand(&robot("\n<xacro:include filename=\"x.xacro\" ns=\"n\"/>")).unwrap_err();
        assert!(
            e.to_string().starts_with("mem.xacro:2: <xacro:include ns=") && e.to_string().contains("not supported"),
            "{e}"
        );
        let e = expand(&robot("<x v=\"$(eval 1+1)\"/>")).unwrap_err();
        assert!(e.to_string().contains("`$(eval 1+1)` is not supported"), "{e}");
        let e = expand(&robot("\n<xacro:nothing/>")).unwrap_err();
        assert!(e.to_string().starts_with("mem.xacro:2: unknown macro `xacro:nothing`"), "{e}");
        let e = expand(&robot("<xacro:if value=\"maybe\"/>")).unwrap_err();
        assert!(e.to_string().contains("not a boolean"), "{e}");
        let e = expand(&robot("<x v=\"$(arg missing)\"/>")).unwrap_err();
        assert!(matches!(&*e.kind, XacroErrorKind::UndefinedArg(a) if a == "missing"), "{e}");
        let e = expand(&robot("<x v=\"$(find no_such_pkg)\"/>")).unwrap_err();
        assert!(e.to_string().contains("package `no_such_pkg` not found") && e.to_string().contains("nowhere"), "{e}");
        let e = expand(&robot(
            "<xacro:property name=\"a\" value=\"${b}\"/><xacro:property name=\"b\" value=\"${a}\"/><x v=\"${a}\"/>",
        ))
        .unwrap_err();
        assert!(e.to_string().contains("circular"), "{e}");
        let e = expand(&robot("<xacro:macro name=\"m\" params=\"a *b\"><x/></xacro:macro>\n<xacro:m a=\"1\"/>"))
            .unwrap_err();
        assert!(e.to_string().starts_with("mem.xacro:2: macro `m`: not enough blocks"), "{e}");
        let e = expand(&robot("<xacro:macro name=\"m\" params=\"a\"><x/></xacro:macro><xacro:m a=\"1\" b=\"2\"/>"))
            .unwrap_err();
        assert!(e.to_string().contains("unknown parameter `b`"), "{e}");
        let e = expand(&robot("<xacro:macro name=\"m\" params=\"\"><xacro:m/></xacro:macro><xacro:m/>")).unwrap_err();
        assert!(e.to_string().contains("deeper than"), "{e}");
        // Inside a macro, the trace says where it was called from.
        let e = expand(&robot("<xacro:macro name=\"m\" params=\"\">\n<x v=\"${1/0}\"/></xacro:macro>\n\n<xacro:m/>"))
            .unwrap_err();
        assert_eq!(e.line, 2, "{e}");
        assert!(e.to_string().contains("in macro `m` called at mem.xacro:4"), "{e}");
    }
}
