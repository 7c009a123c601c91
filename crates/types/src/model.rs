//! The network families of the actor and critic (docs/paper.md §1.4–1.10).

crate::named_enum! {
    /// The network family, by the name used on the command line, in configs, in
    /// `PolicyWeights.model` and in checkpoint manifests.
    pub enum ModelKind: "model" {
        /// Equivariant SAC over D4 (`equi_both_d`; `equi_d4` is accepted too).
        Equi = "equi" | "equi_d4",
        /// The CNN SAC baseline, 'conv' variant.
        Cnn = "cnn",
        /// SEN fc2: CNN encoder, equivariant heads.
        Sen = "sen",
        /// FERM: CURL's encoder with MLP heads, contrastive pre-training and a contrastive step per
        /// update (docs/paper.md §1.10).
        Ferm = "ferm",
    }
}
