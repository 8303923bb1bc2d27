"""The torch device rule of every detector user (the detector node, `monet process`, `eval`,
`train`, `label`, `pipeline`): which device strings exist on this machine."""
from monet_ros.config import ConfigError


def check_device(owner, device, field='device'):
    """A torch device string that exists here: '', None or 'auto' (CUDA when present), 'cpu',
    'cuda' or 'cuda:N' (with CUDA available and N < the device count). Returns the device to
    pass on (None for auto). ConfigError naming `field` otherwise."""
    if device in (None, '', 'auto'):
        return None
    text = str(device)
    if text == 'cpu':
        return text
    if text == 'cuda' or (text.startswith('cuda:') and text[5:].isdigit()):
        import torch
        if not torch.cuda.is_available():
            raise ConfigError(owner, field, f'{text!r}: CUDA is not available on this machine '
                              "(use 'cpu' or 'auto')")
        index = int(text[5:]) if ':' in text else 0
        if index >= torch.cuda.device_count():
            raise ConfigError(owner, field, f'{text!r}: only {torch.cuda.device_count()} '
                              'CUDA device(s)')
        return text
    raise ConfigError(owner, field, f'expected auto, cpu, cuda or cuda:N, got {text!r}')
