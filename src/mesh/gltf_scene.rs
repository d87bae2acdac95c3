//! Walks a glTF node hierarchy without recursion and lists every mesh instance
//! with its world transform.
//!
//! The gltf crate accepts node cycles (`0 -> 1 -> 0`), and a recursive walk then
//! overflows the stack. This walk keeps an explicit stack and a per-node state
//! (unvisited / on the current path / done): reaching a node that is on the path is
//! a cycle; reaching a finished node again (a node with two parents, which glTF
//! forbids) skips it with a warning, which also bounds the work by the node count.

use std::path::Path;

use glam::{Mat4, Quat, Vec3, Vec4};
use gltf::json::Root;

use super::MeshError;

/// One placement of a glTF mesh in the scene.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct MeshInstance {
    pub node: usize,
    pub mesh: usize,
    /// Node-to-world transform (product of the node's and its ancestors' transforms).
    pub world: Mat4,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum VisitState {
    Unvisited,
    OnPath,
    Done,
}

enum Frame {
    Enter { node: usize, parent_world: Mat4 },
    Exit { node: usize },
}

/// The local transform of node `node`: its `matrix`, or T * R * S.
fn local_transform(root: &Root, node: usize) -> Mat4 {
    let Some(json) = root.nodes.get(node) else { return Mat4::IDENTITY };
    if let Some(matrix) = json.matrix {
        return Mat4::from_cols_array(&matrix);
    }
    let translation = json.translation.map_or(Vec3::ZERO, Vec3::from_array);
    // glTF requires unit quaternions; normalise anyway so a sloppy exporter's
    // rotation does not also scale.
    let rotation = json.rotation.map_or(Quat::IDENTITY, |q| Vec4::from_array(q.0).try_normalize().map_or(Quat::IDENTITY, Quat::from_vec4));
    let scale = json.scale.map_or(Vec3::ONE, Vec3::from_array);
    Mat4::from_scale_rotation_translation(scale, rotation, translation)
}

/// The nodes to start from, each with whether re-reaching it deserves a warning.
///
/// The default scene (`scene`), else scene 0; with no scenes at all, every root
/// node (nobody's child) and then every node not reached yet, so that nodes
/// hanging only off a cycle still reveal it.
fn start_nodes(root: &Root) -> Vec<(usize, bool)> {
    let scene = root.scene.and_then(|index| root.scenes.get(index.value())).or_else(|| root.scenes.first());
    if let Some(scene) = scene {
        return scene.nodes.iter().map(|n| (n.value(), true)).collect();
    }
    let mut has_parent = vec![false; root.nodes.len()];
    for node in &root.nodes {
        for child in node.children.iter().flatten() {
            if let Some(flag) = has_parent.get_mut(child.value()) {
                *flag = true;
            }
        }
    }
    let parentless = (0..root.nodes.len()).filter(|&n| !has_parent[n]).map(|n| (n, true));
    parentless.chain((0..root.nodes.len()).map(|n| (n, false))).collect()
}

/// Lists every mesh instance of the scene in depth-first order (children in the
/// order given), with world transforms. Errors on a node cycle or a dangling node
/// index; pushes a warning when nodes are reached more than once.
pub(crate) fn collect_mesh_instances(root: &Root, path: &Path, warnings: &mut Vec<String>) -> Result<Vec<MeshInstance>, MeshError> {
    let node_count = root.nodes.len();
    let mut state = vec![VisitState::Unvisited; node_count];
    let mut instances = Vec::new();
    let mut reached_again = 0usize;
    let mut stack = Vec::new();
    for (start, warn_if_done) in start_nodes(root) {
        match state.get(start) {
            None => return Err(MeshError::gltf(path, format!("scene refers to node {start}, which does not exist"))),
            Some(VisitState::Unvisited) => {}
            Some(_) => {
                reached_again += usize::from(warn_if_done);
                continue;
            }
        }
        stack.push(Frame::Enter { node: start, parent_world: Mat4::IDENTITY });
        while let Some(frame) = stack.pop() {
            let (node, parent_world) = match frame {
                Frame::Exit { node } => {
                    state[node] = VisitState::Done;
                    continue;
                }
                Frame::Enter { node, parent_world } => (node, parent_world),
            };
            match state.get(node) {
                None => return Err(MeshError::gltf(path, format!("a node refers to child node {node}, which does not exist"))),
                Some(VisitState::OnPath) => return Err(MeshError::NodeCycle { path: path.to_path_buf(), node }),
                Some(VisitState::Done) => {
                    reached_again += 1;
                    continue;
                }
                Some(VisitState::Unvisited) => {}
            }
            state[node] = VisitState::OnPath;
            let world = parent_world * local_transform(root, node);
            let json = &root.nodes[node];
            if let Some(mesh) = json.mesh {
                instances.push(MeshInstance { node, mesh: mesh.value(), world });
            }
            stack.push(Frame::Exit { node });
            // Reversed so children are visited in their listed order.
            for child in json.children.iter().flatten().rev() {
                stack.push(Frame::Enter { node: child.value(), parent_world: world });
            }
        }
    }
    if reached_again > 0 {
        warnings.push(format!(
            "{reached_again} node references reach an already placed node (glTF nodes have at most one parent); those repeats were skipped"
        ));
    }
    Ok(instances)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn root(json: &str) -> Root {
        gltf::json::deserialize::from_str(json).unwrap()
    }

    #[test]
    fn composes_parent_and_child_transforms() {
        let r = root(
            r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[
                {"translation":[1,0,0],"children":[1]},
                {"scale":[2,2,2],"mesh":0}],"meshes":[]}"#,
        );
        let instances = collect_mesh_instances(&r, Path::new("t.gltf"), &mut Vec::new()).unwrap();
        assert_eq!(instances.len(), 1);
        assert_eq!(instances[0].world.transform_point3(Vec3::ONE), Vec3::new(3.0, 2.0, 2.0));
    }

    #[test]
    fn detects_cycles_without_recursion_even_when_very_deep() {
        // A chain of 200 000 nodes whose last node points back to the first: a
        // recursive walk would overflow the stack long before the cycle is found.
        let n = 200_000;
        let nodes: Vec<String> = (0..n).map(|i| format!(r#"{{"children":[{}]}}"#, (i + 1) % n)).collect();
        let json = format!(r#"{{"asset":{{"version":"2.0"}},"scenes":[{{"nodes":[0]}}],"nodes":[{}]}}"#, nodes.join(","));
        let r = root(&json);
        let err = collect_mesh_instances(&r, Path::new("deep.gltf"), &mut Vec::new()).unwrap_err();
        assert_eq!(err.to_string(), "deep.gltf: node cycle at node 0");
    }

    #[test]
    fn sceneless_files_walk_root_nodes_and_still_find_cycles() {
        let cyclic = root(r#"{"asset":{"version":"2.0"},"nodes":[{"children":[1]},{"children":[0]}]}"#);
        assert!(matches!(collect_mesh_instances(&cyclic, Path::new("c.gltf"), &mut Vec::new()), Err(MeshError::NodeCycle { node: 0, .. })));
        let forest = root(r#"{"asset":{"version":"2.0"},"nodes":[{"mesh":0},{"children":[0]},{"mesh":1}],"meshes":[]}"#);
        let mut warnings = Vec::new();
        let instances = collect_mesh_instances(&forest, Path::new("f.gltf"), &mut warnings).unwrap();
        let placed: Vec<usize> = instances.iter().map(|i| i.node).collect();
        assert_eq!(placed, vec![0, 2]);
        assert!(warnings.is_empty(), "{warnings:?}");
    }

    #[test]
    fn a_node_with_two_parents_is_placed_once_with_a_warning() {
        let r = root(
            r#"{"asset":{"version":"2.0"},"scenes":[{"nodes":[0,1]}],"nodes":[{"children":[2]},{"children":[2]},{"mesh":0}],"meshes":[]}"#,
        );
        let mut warnings = Vec::new();
        let instances = collect_mesh_instances(&r, Path::new("d.gltf"), &mut warnings).unwrap();
        assert_eq!(instances.len(), 1);
        assert_eq!(warnings.len(), 1);
    }
}
