// Twin of shaders/featuregrid.glsl's #else branch: a pure MLP has no grids; its input is the encoding alone.

fn grid_set_key() {
}

fn network_input_block(block: i32) -> vec4<f32> {
    return encoded_block(block);
}
