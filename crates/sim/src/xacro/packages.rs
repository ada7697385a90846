//! Where `$(find pkg)` and `package://pkg/...` point: a ROS package is a folder with a
//! `package.xml` whose `<name>` is the package's name.

use std::path::{Path, PathBuf};

/// The places packages are looked for, in order: folders given by the user, then those of
/// `ROS_PACKAGE_PATH` (both searched recursively, as `rospack` does), then the install
/// prefixes of `AMENT_PREFIX_PATH` (`PREFIX/share/PKG`, as `ament_index` does).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PackagePath {
    /// Folders that are a package or hold packages (at any depth up to [`MAX_DEPTH`]).
    pub dirs: Vec<PathBuf>,
    /// ROS 2 install prefixes; a package `PKG` is `PREFIX/share/PKG`.
    pub prefixes: Vec<PathBuf>,
}

/// How deep below a search folder a package is looked for (a colcon workspace's
/// `src/vendor/repo/pkg` is 3 deep).
pub const MAX_DEPTH: usize = 5;

impl PackagePath {
    /// Only the given folders.
    pub fn new(dirs: impl IntoIterator<Item = PathBuf>) -> Self {
        Self { dirs: dirs.into_iter().collect(), prefixes: Vec::new() }
    }

    /// Adds the folders of `ROS_PACKAGE_PATH` and the prefixes of `AMENT_PREFIX_PATH`
    /// (after those already given).
    pub fn with_environment(mut self) -> Self {
        let split = |var: &str| -> Vec<PathBuf> {
            std::env::var_os(var)
                .map(|v| std::env::split_paths(&v).filter(|p| !p.as_os_str().is_empty()).collect())
                .unwrap_or_default()
        };
        self.dirs.extend(split("ROS_PACKAGE_PATH"));
        self.prefixes.extend(split("AMENT_PREFIX_PATH"));
        self
    }

    /// The folder of package `name`, if some search place has it.
    pub fn find(&self, name: &str) -> Option<PathBuf> {
        if name.is_empty() || name.contains(['/', '\\']) {
            return None;
        }
        self.dirs.iter().find_map(|d| crawl(d, name, 0)).or_else(|| {
            self.prefixes.iter().find_map(|p| {
                let share = p.join("share").join(name);
                let indexed = p.join("share/ament_index/resource_index/packages").join(name).is_file();
                (indexed || share.join("package.xml").is_file()).then_some(share)
            })
        })
    }

    /// The search places, for messages ("nowhere" when there are none).
    pub fn describe(&self) -> String {
        let mut parts: Vec<String> = self.dirs.iter().map(|d| d.display().to_string()).collect();
        parts.extend(self.prefixes.iter().map(|p| format!("{}/share", p.display())));
        if parts.is_empty() {
            "nowhere (no --package-path, ROS_PACKAGE_PATH or AMENT_PREFIX_PATH)".into()
        } else {
            parts.join(", ")
        }
    }
}

/// Looks for the package in `dir` and below it; a package's own folder is not searched
/// further (packages do not nest), nor are hidden folders or those marked to be ignored.
fn crawl(dir: &Path, name: &str, depth: usize) -> Option<PathBuf> {
    let manifest = dir.join("package.xml");
    if manifest.is_file() {
        return (package_name(&manifest).as_deref() == Some(name)).then(|| dir.to_path_buf());
    }
    if depth >= MAX_DEPTH || ["COLCON_IGNORE", "CATKIN_IGNORE", "AMENT_IGNORE"].iter().any(|m| dir.join(m).exists()) {
        return None;
    }
    let mut subdirs: Vec<PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()) && !e.file_name().to_string_lossy().starts_with('.'))
        .map(|e| e.path())
        .collect();
    // Sorted, so that the same tree always gives the same answer.
    subdirs.sort();
    // The folder named like the package first: the common layout, found without a crawl.
    if let Some(i) = subdirs.iter().position(|d| d.file_name().is_some_and(|f| f == name)) {
        let d = subdirs.remove(i);
        subdirs.insert(0, d);
    }
    subdirs.iter().find_map(|d| crawl(d, name, depth + 1))
}

/// The `<name>` of a `package.xml` (its folder's name when it has none).
fn package_name(manifest: &Path) -> Option<String> {
    let text = std::fs::read_to_string(manifest).ok()?;
    let declared = text
        .split_once("<name>")
        .and_then(|(_, rest)| rest.split_once("</name>"))
        .map(|(name, _)| name.trim().to_string());
    declared.or_else(|| manifest.parent()?.file_name().map(|f| f.to_string_lossy().into_owned()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn finds_by_declared_name_below_a_search_folder_and_in_prefixes() {
        let root = std::env::temp_dir().join(format!("rlnav-pkgs-{}", std::process::id()));
        let ws = root.join("ws/src/repo");
        std::fs::create_dir_all(ws.join("folder_differs")).unwrap();
        std::fs::write(ws.join("folder_differs/package.xml"), "<package><name>my_pkg</name></package>").unwrap();
        std::fs::create_dir_all(ws.join("ignored/hidden_pkg")).unwrap();
        std::fs::write(ws.join("ignored/COLCON_IGNORE"), "").unwrap();
        std::fs::write(ws.join("ignored/hidden_pkg/package.xml"), "<package><name>hidden_pkg</name></package>")
            .unwrap();
        std::fs::create_dir_all(root.join("install/share/ament_index/resource_index/packages")).unwrap();
        std::fs::write(root.join("install/share/ament_index/resource_index/packages/other_pkg"), "").unwrap();

        let mut p = PackagePath::new([root.join("ws")]);
        assert_eq!(p.find("my_pkg"), Some(ws.join("folder_differs")));
        assert_eq!(p.find("hidden_pkg"), None);
        assert_eq!(p.find("other_pkg"), None);
        p.prefixes.push(root.join("install"));
        assert_eq!(p.find("other_pkg"), Some(root.join("install/share/other_pkg")));
        assert_eq!(p.find("../etc"), None);
        assert!(p.describe().contains("install/share"));
        assert!(PackagePath::default().describe().starts_with("nowhere"));
        std::fs::remove_dir_all(&root).unwrap();
    }
}
