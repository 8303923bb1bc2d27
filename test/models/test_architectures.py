"""The registry builds every detector with the stated shapes; a CPM training step works."""
import pytest
import torch

from monet_ros.models import MODELS, build_model, fuse_for_inference


def randomize_batchnorm(model, seed=0):
    """Non-trivial running statistics and affine parameters, so fusion is really tested."""
    generator = torch.Generator().manual_seed(seed)
    for module in model.modules():
        if isinstance(module, torch.nn.BatchNorm2d):
            n = module.num_features
            module.running_mean.copy_(torch.randn(n, generator=generator) * 0.1)
            module.running_var.copy_(torch.rand(n, generator=generator) + 0.5)
            module.weight.data.copy_(torch.rand(n, generator=generator) + 0.5)
            module.bias.data.copy_(torch.randn(n, generator=generator) * 0.1)


def test_registry_names_and_errors():
    assert set(MODELS) == {'cpm', 'hourglass', 'small'}
    with pytest.raises(ValueError, match='unknown architecture'):
        build_model('resnet', 14)
    with pytest.raises(ValueError, match='num_keypoints'):
        build_model('small', 0)


def test_cpm_forward_backward_step_on_cpu():
    torch.manual_seed(0)
    model = build_model('cpm', 14)
    assert model.input_size == (368, 368) and model.heatmap_size == (46, 46)
    images = torch.rand(1, 3, 368, 368)
    target = torch.zeros(1, 14, 46, 46)
    target[:, :, 20:23, 10:13] = 1.0
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    losses = []
    for _ in range(2):
        stages = model(images)
        assert len(stages) == 5, 'intermediate supervision: one output per stage'
        assert all(s.shape == (1, 14, 46, 46) for s in stages)
        loss = sum(torch.mean((s - target) ** 2) for s in stages)
        optimizer.zero_grad()
        loss.backward()
        grads = [p.grad for p in model.parameters()]
        assert all(g is not None and torch.isfinite(g).all() for g in grads)
        # every stage receives gradient (intermediate supervision reaches stage 1 directly)
        for stage in model.stages:
            assert stage.head.weight.grad.abs().sum() > 0
        optimizer.step()
        losses.append(loss.item())
    assert losses[-1] < losses[0]


@pytest.mark.parametrize('name, input_size, heatmap_size, num_outputs', [
    ('hourglass', (256, 256), (64, 64), 2),
    ('small', (256, 256), (64, 64), 1),
])
def test_shapes(name, input_size, heatmap_size, num_outputs):
    model = build_model(name, 5).eval()
    assert model.input_size == input_size and model.heatmap_size == heatmap_size
    with torch.inference_mode():
        out = model(torch.rand(2, 3, *input_size))
    assert len(out) == num_outputs
    assert all(o.shape == (2, 5, *heatmap_size) for o in out)


def test_options_change_the_network():
    model = build_model('cpm', 3, num_stages=2, width=16, input_size=(96, 128))
    assert model.heatmap_size == (12, 16)
    out = model(torch.rand(1, 3, 96, 128))
    assert len(out) == 2 and out[-1].shape == (1, 3, 12, 16)
    assert model.model_options == {'num_stages': 2, 'width': 16, 'input_size': (96, 128)}
    with pytest.raises(ValueError, match='multiple of 8'):
        build_model('small', 3, input_size=(250, 256))


@pytest.mark.parametrize('name', ['small', 'hourglass'])
def test_fused_model_matches_unfused(name):
    torch.manual_seed(1)
    options = {'features': 32} if name == 'hourglass' else {}
    model = build_model(name, 4, **options)
    randomize_batchnorm(model)
    model.eval()
    images = torch.rand(2, 3, *model.input_size)
    with torch.inference_mode():
        reference = model(images)[-1]
        fused = fuse_for_inference(model)(images)[-1]
    assert not any(isinstance(m, torch.nn.BatchNorm2d) for m in model.modules())
    assert torch.allclose(fused, reference, atol=1e-4 * reference.abs().max().item())
    with pytest.raises(ValueError, match='eval mode'):
        fuse_for_inference(build_model(name, 4, **options))
