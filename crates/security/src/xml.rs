//! Reading back the governance and permissions a node was given: just enough of each document to
//! say, naming the file, when it does not parse, is for another domain, or grants nothing to the
//! node's identity. The DDS Security plugins read the documents in full.

use quick_xml::Reader;
use quick_xml::events::Event;

/// An element: its local name, its text, its children.
#[derive(Debug, Default)]
pub struct Element {
    /// Local name (without a namespace prefix).
    pub name: String,
    /// The text directly inside it, trimmed.
    pub text: String,
    /// Child elements in order.
    pub children: Vec<Element>,
}

impl Element {
    /// Parses a whole document; the error says where it stops parsing.
    pub fn parse(xml: &str) -> Result<Element, String> {
        let mut reader = Reader::from_str(xml);
        reader.config_mut().trim_text(true);
        let mut stack = vec![Element::default()];
        loop {
            let at = reader.buffer_position();
            match reader.read_event().map_err(|e| format!("not XML (at byte {at}): {e}"))? {
                Event::Start(s) => stack.push(Element { name: local(&s), ..Default::default() }),
                Event::Empty(s) => {
                    let e = Element { name: local(&s), ..Default::default() };
                    stack.last_mut().expect("the root is never popped").children.push(e);
                }
                Event::End(_) => {
                    let done = stack.pop().expect("the reader checks that tags match");
                    match stack.last_mut() {
                        Some(parent) => parent.children.push(done),
                        None => return Err("unbalanced tags".into()),
                    }
                }
                Event::Text(t) => {
                    if let Some(e) = stack.last_mut() {
                        e.text.push_str(t.into_inner().trim());
                    }
                }
                Event::Eof => break,
                _ => {}
            }
        }
        if stack.len() != 1 {
            return Err("the document ends inside an element".into());
        }
        let mut root = stack.pop().expect("checked above");
        match root.children.len() {
            1 => Ok(root.children.remove(0)),
            0 => Err("no root element".into()),
            _ => Err("more than one root element".into()),
        }
    }

    /// The children named `name`.
    pub fn all<'a, 'n>(&'a self, name: &'n str) -> impl Iterator<Item = &'a Element> + use<'a, 'n> {
        self.children.iter().filter(move |c| c.name == name)
    }

    /// The first child named `name`.
    pub fn get(&self, name: &str) -> Option<&Element> {
        self.all(name).next()
    }

    /// The elements at `path` (names separated by '/') below this one.
    pub fn at<'a>(&'a self, path: &str) -> Vec<&'a Element> {
        let mut here = vec![self];
        for part in path.split('/') {
            here = here.into_iter().flat_map(|e| e.all(part)).collect();
        }
        here
    }
}

fn local(s: &quick_xml::events::BytesStart<'_>) -> String {
    let name = s.local_name();
    let text: &str = name.as_ref();
    text.to_string()
}

/// Whether a `<domains>` element (ids and id ranges, DDS Security §9.4.1.2.3) holds `domain`.
pub fn domains_hold(domains: &Element, domain: u16) -> bool {
    let d = u32::from(domain);
    let num = |e: Option<&Element>| e.and_then(|e| e.text.parse::<u32>().ok());
    domains.all("id").any(|id| num(Some(id)) == Some(d))
        || domains.all("id_range").any(|r| {
            let min = num(r.get("min")).unwrap_or(0);
            let max = num(r.get("max")).unwrap_or(u32::MAX);
            (min..=max).contains(&d)
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_and_finds_domains() {
        let e = Element::parse("<?xml version=\"1.0\"?><dds><r><domains><id>3</id><id_range><min>10</min><max>20</max></id_range></domains></r></dds>").unwrap();
        let d = e.at("r/domains");
        assert_eq!(d.len(), 1);
        assert!(domains_hold(d[0], 3) && domains_hold(d[0], 15) && !domains_hold(d[0], 4));
        for bad in ["<dds><a></dds>", "", "<a/><b/>", "<dds>"] {
            assert!(Element::parse(bad).is_err(), "{bad}");
        }
    }
}
