//! The XML tree xacro works on: elements keep the file and line they came from, so that an
//! error deep in a macro expansion can still say where the offending text was written.
//!
//! Parsing is quick-xml's; comments and processing instructions are dropped (a robot
//! description does not need them), CDATA is kept verbatim.

use quick_xml::events::{BytesStart, Event};
use std::rc::Rc;

/// Where an element was written.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Pos {
    /// The file, as given to the parser.
    pub file: Rc<str>,
    /// 1-based line of the element's `<`.
    pub line: usize,
}

/// A node of the tree.
#[derive(Clone, Debug)]
pub(crate) enum Node {
    Element(Element),
    /// Text (entities already resolved) and the line it starts on (0 when generated).
    Text(String, usize),
    /// A CDATA section, kept and written as it was.
    CData(String),
}

/// An element: its qualified name (`xacro:macro`, `link`), its attributes in document order,
/// its children and where it was written.
#[derive(Clone, Debug)]
pub(crate) struct Element {
    pub name: String,
    pub attrs: Vec<(String, String)>,
    pub children: Vec<Node>,
    pub pos: Pos,
}

impl Element {
    /// The value of an attribute.
    pub fn attr(&self, name: &str) -> Option<&str> {
        self.attrs.iter().find(|(k, _)| k == name).map(|(_, v)| v.as_str())
    }

    /// Sets an attribute, replacing its value if it exists (keeping its place).
    pub fn set_attr(&mut self, name: &str, value: String) {
        match self.attrs.iter_mut().find(|(k, _)| k == name) {
            Some(slot) => slot.1 = value,
            None => self.attrs.push((name.to_string(), value)),
        }
    }
}

/// A parse failure: the line and what the parser said.
#[derive(Debug)]
pub(crate) struct ParseError {
    pub line: usize,
    pub message: String,
}

/// Counts lines up to byte offsets that only grow (the reader moves forward).
struct LineCounter<'a> {
    text: &'a [u8],
    offset: usize,
    line: usize,
}

impl LineCounter<'_> {
    fn line_at(&mut self, offset: usize) -> usize {
        let offset = offset.min(self.text.len());
        if offset >= self.offset {
            self.line += self.text[self.offset..offset].iter().filter(|b| **b == b'\n').count();
        } else {
            // An error position may lie before the last event; count from the start.
            self.line = 1 + self.text[..offset].iter().filter(|b| **b == b'\n').count();
        }
        self.offset = offset;
        self.line
    }
}

/// Parses a document; returns its root element.
pub(crate) fn parse(file: &Rc<str>, text: &str) -> Result<Element, ParseError> {
    let mut reader = quick_xml::Reader::from_str(text);
    let mut lines = LineCounter { text: text.as_bytes(), offset: 0, line: 1 };
    let mut stack: Vec<Element> = Vec::new();
    let mut root: Option<Element> = None;
    loop {
        let start = reader.buffer_position() as usize;
        let event = reader.read_event().map_err(|e| ParseError {
            line: lines.line_at(reader.error_position() as usize),
            message: e.to_string(),
        })?;
        let line = lines.line_at(start);
        let err = |message: String| ParseError { line, message };
        match event {
            Event::Start(e) => {
                let el = element(file, &e, line).map_err(err)?;
                stack.push(el);
            }
            Event::Empty(e) => {
                let el = element(file, &e, line).map_err(err)?;
                match stack.last_mut() {
                    Some(parent) => parent.children.push(Node::Element(el)),
                    None if root.is_none() => root = Some(el),
                    None => return Err(err("a second root element".into())),
                }
            }
            Event::End(_) => {
                let el = stack.pop().ok_or_else(|| err("closing tag without an opening one".into()))?;
                match stack.last_mut() {
                    Some(parent) => parent.children.push(Node::Element(el)),
                    None if root.is_none() => root = Some(el),
                    None => return Err(err("a second root element".into())),
                }
            }
            Event::Text(t) => {
                let s = t.xml_content().map_err(|e| err(e.to_string()))?;
                push_text(&mut stack, &s, line);
            }
            Event::GeneralRef(r) => {
                let s = match r.resolve_char_ref().map_err(|e| err(e.to_string()))? {
                    Some(c) => c.to_string(),
                    None => {
                        let name = r.decode().map_err(|e| err(e.to_string()))?;
                        quick_xml::escape::resolve_predefined_entity(&name)
                            .ok_or_else(|| err(format!("unknown entity `&{name};`")))?
                            .to_string()
                    }
                };
                push_text(&mut stack, &s, line);
            }
            Event::CData(c) => {
                if let Some(parent) = stack.last_mut() {
                    parent.children.push(Node::CData(c.decode().map_err(|e| err(e.to_string()))?.into_owned()));
                }
            }
            Event::Eof => break,
            // Comments, the declaration, processing instructions and DOCTYPE are dropped.
            _ => {}
        }
    }
    if let Some(open) = stack.last() {
        return Err(ParseError { line: open.pos.line, message: format!("`<{}>` is never closed", open.name) });
    }
    root.ok_or(ParseError { line: 1, message: "no root element".into() })
}

/// Appends text to the open element, joining it to the text before (entities arrive apart).
fn push_text(stack: &mut [Element], s: &str, line: usize) {
    // Text outside the root element can only be whitespace (quick-xml rejects the rest).
    let Some(parent) = stack.last_mut() else { return };
    match parent.children.last_mut() {
        Some(Node::Text(prev, _)) => prev.push_str(s),
        _ => parent.children.push(Node::Text(s.to_string(), line)),
    }
}

fn element(file: &Rc<str>, e: &BytesStart, line: usize) -> Result<Element, String> {
    let name = String::from_utf8(e.name().as_ref().to_vec()).map_err(|e| e.to_string())?;
    let mut attrs = Vec::new();
    for a in e.attributes().with_checks(true) {
        let a = a.map_err(|e| e.to_string())?;
        let key = String::from_utf8(a.key.as_ref().to_vec()).map_err(|e| e.to_string())?;
        let raw = std::str::from_utf8(&a.value).map_err(|e| e.to_string())?;
        // XML attribute-value normalisation: literal line breaks and tabs become spaces
        // (character references such as `&#10;` are kept), as every conforming parser does.
        let normalised = raw.replace("\r\n", " ").replace(['\r', '\n', '\t'], " ");
        let value = quick_xml::escape::unescape(&normalised).map_err(|e| format!("attribute `{key}`: {e}"))?;
        attrs.push((key, value.into_owned()));
    }
    Ok(Element { name, attrs, children: Vec::new(), pos: Pos { file: file.clone(), line } })
}

/// Writes a document: the XML declaration and the root element.
pub(crate) fn write(root: &Element) -> String {
    let mut out = String::from("<?xml version=\"1.0\"?>\n");
    write_element(root, &mut out);
    out.push('\n');
    out
}

fn write_element(el: &Element, out: &mut String) {
    out.push('<');
    out.push_str(&el.name);
    for (k, v) in &el.attrs {
        out.push(' ');
        out.push_str(k);
        out.push_str("=\"");
        out.push_str(&quick_xml::escape::escape(v.as_str()));
        out.push('"');
    }
    if el.children.is_empty() {
        out.push_str("/>");
        return;
    }
    out.push('>');
    for c in &el.children {
        match c {
            Node::Element(e) => write_element(e, out),
            Node::Text(t, _) => out.push_str(&quick_xml::escape::escape(t.as_str())),
            Node::CData(c) => {
                out.push_str("<![CDATA[");
                out.push_str(c);
                out.push_str("]]>");
            }
        }
    }
    out.push_str("</");
    out.push_str(&el.name);
    out.push('>');
}

#[cfg(test)]
mod tests {
    use super::*;

    fn doc(text: &str) -> Result<Element, ParseError> {
        parse(&Rc::from("t.xml"), text)
    }

    #[test]
    fn lines_entities_and_normalised_attributes() {
        let root = doc("<?xml version=\"1.0\"?>\n<!-- c -->\n<robot a=\"x\n  y\" b=\"&lt;&#65;\">\n  <link\n    name=\"l\"/>\n  t&amp;u\n</robot>\n")
            .unwrap();
        assert_eq!(root.pos.line, 3);
        assert_eq!(root.attr("a"), Some("x   y"));
        assert_eq!(root.attr("b"), Some("<A"));
        // The start tag spans lines 3-4; `<link` is on line 5 and its `/>` on line 6.
        let Node::Element(link) = &root.children[1] else { panic!("{:?}", root.children) };
        assert_eq!((link.name.as_str(), link.pos.line, link.attr("name")), ("link", 5, Some("l")));
        let Node::Text(t, line) = &root.children[2] else { panic!("{:?}", root.children) };
        assert_eq!((t.trim(), *line), ("t&u", 6));
        let written = write(&root);
        assert!(written.contains("b=\"&lt;A\"") && written.contains("t&amp;u"), "{written}");
        // What is written parses back to the same tree.
        let again = doc(&written).unwrap();
        assert_eq!(again.attrs, root.attrs);
    }

    #[test]
    fn malformed_documents_say_the_line() {
        let e = doc("<robot>\n<link>\n</robot>").unwrap_err();
        assert_eq!(e.line, 3, "{}", e.message);
        let e = doc("<robot>\n  <link name=\"a\" name=\"b\"/>\n</robot>").unwrap_err();
        assert_eq!(e.line, 2, "{}", e.message);
        let e = doc("<robot>\n  &nbsp;\n</robot>").unwrap_err();
        assert!(e.line == 2 && e.message.contains("nbsp"), "{}: {}", e.line, e.message);
        assert!(doc("<a/><b/>").is_err());
        assert!(doc("   ").is_err());
    }
}
