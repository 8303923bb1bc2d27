"""Fixtures of the `monet label` tests: a real server process (helpers.label_app) and a
real headless Chromium (Debian's chromium + chromium-driver, driven by Selenium through
/usr/bin/chromedriver; `make test` installs them with apt-get when missing)."""
import os
import shutil
import time

from helpers.label_app import free_port, label_server  # noqa: F401 (the tests' import)
import pytest

CHROMEDRIVER = '/usr/bin/chromedriver'
# Names Chromium resolves to 127.0.0.1 (a DNS rebinding: another site's name, this server).
REBOUND_HOST = 'rebound.example'


@pytest.fixture(scope='module')
def browser():
    """A headless Chromium (Selenium with the system chromedriver; never downloaded)."""
    if not (os.path.exists(CHROMEDRIVER) and (shutil.which('chromium')
                                              or shutil.which('chromium-browser'))):
        pytest.skip('Debian chromium + chromium-driver not installed (apt-get install -y '
                    'chromium chromium-driver; `make test` does it)')
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    for arg in ('--headless=new', '--no-sandbox', '--disable-dev-shm-usage', '--disable-gpu',
                '--force-device-scale-factor=1', '--window-size=1700,1000',
                f'--host-resolver-rules=MAP {REBOUND_HOST} 127.0.0.1'):
        options.add_argument(arg)
    binary = shutil.which('chromium') or shutil.which('chromium-browser')
    options.binary_location = binary
    driver = webdriver.Chrome(service=Service(executable_path=CHROMEDRIVER), options=options)
    driver.set_window_size(1700, 1000)
    try:
        yield driver
    finally:
        driver.quit()


class LabelPage:
    """The page of `monet label` in a Selenium driver: real mouse and keyboard events
    (Selenium actions at viewport coordinates), state read from window.monetLabel."""

    def __init__(self, driver, url):
        self.driver = driver
        self.url = url

    def open(self, t, timeout=60.0):
        self.driver.get(f'{self.url}/?t={t}')
        self.wait_idle(timeout)
        assert self.state('t') == t

    def state(self, expr):
        return self.driver.execute_script(f'return window.monetLabel.{expr};')

    def wait_idle(self, timeout=30.0):
        """Until the page has loaded and every request it sent was answered."""
        deadline = time.monotonic() + timeout
        while True:
            done = self.driver.execute_script(
                'const s = window.monetLabel; return Boolean(s && s.ready && s.busy === 0);')
            if done:
                error = self.state('error')
                assert error is None, f'page error: {error}'
                return
            if time.monotonic() > deadline:
                raise AssertionError('the page did not settle in time')
            time.sleep(0.05)

    def client_xy(self, camera, u, v):
        return self.driver.execute_script(
            'return window.monetLabel.toClient(arguments[0], arguments[1], arguments[2]);',
            camera, float(u), float(v))

    def _pointer(self):
        from selenium.webdriver.common.actions.action_builder import ActionBuilder
        return ActionBuilder(self.driver, duration=0)

    def click(self, camera, u, v):
        """A left click at image pixel (u, v) of a camera (rounded to a screen pixel)."""
        x, y = self.client_xy(camera, u, v)
        actions = self._pointer()
        actions.pointer_action.move_to_location(round(x), round(y))
        actions.pointer_action.click()
        actions.perform()

    def drag(self, camera, start, end):
        """Press at image pixel `start`, move to `end` in steps, release."""
        x0, y0 = self.client_xy(camera, *start)
        x1, y1 = self.client_xy(camera, *end)
        actions = self._pointer()
        actions.pointer_action.move_to_location(round(x0), round(y0))
        actions.pointer_action.pointer_down()
        for f in (0.3, 0.6, 1.0):
            actions.pointer_action.move_to_location(round(x0 + f * (x1 - x0)),
                                                    round(y0 + f * (y1 - y0)))
        actions.pointer_action.pointer_up()
        actions.perform()

    def wheel(self, camera, u, v, delta_y):
        """A mouse-wheel turn over image pixel (u, v) (negative delta_y zooms in)."""
        from selenium.webdriver.common.action_chains import ActionChains
        from selenium.webdriver.common.actions.wheel_input import ScrollOrigin
        canvas = self.driver.find_element('id', f'view-{camera}')
        x, y = self.client_xy(camera, u, v)
        rect = canvas.rect
        origin = ScrollOrigin.from_element(canvas, round(x - rect['x'] - rect['width'] / 2),
                                           round(y - rect['y'] - rect['height'] / 2))
        ActionChains(self.driver).scroll_from_origin(origin, 0, int(delta_y)).perform()

    def pan(self, camera, start, end):
        """A right-button drag from image pixel `start` to `end`."""
        from selenium.webdriver.common.actions.mouse_button import MouseButton
        x0, y0 = self.client_xy(camera, *start)
        x1, y1 = self.client_xy(camera, *end)
        actions = self._pointer()
        actions.pointer_action.move_to_location(round(x0), round(y0))
        actions.pointer_action.pointer_down(MouseButton.RIGHT)
        actions.pointer_action.move_to_location(round(x1), round(y1))
        actions.pointer_action.pointer_up(MouseButton.RIGHT)
        actions.perform()

    def hover(self, camera):
        x, y = self.client_xy(camera, 1.0, 1.0)
        actions = self._pointer()
        actions.pointer_action.move_to_location(round(x), round(y))
        actions.perform()

    def key(self, key, ctrl=False):
        from selenium.webdriver.common.action_chains import ActionChains
        from selenium.webdriver.common.keys import Keys
        chain = ActionChains(self.driver)
        if ctrl:
            chain.key_down(Keys.CONTROL).send_keys(key).key_up(Keys.CONTROL)
        else:
            chain.send_keys(key)
        chain.perform()

    def select(self, keypoint):
        self.driver.find_element('css selector', f'#keypoints li[data-keypoint="{keypoint}"]'
                                 ).click()
        self.wait_idle()
        assert self.state('summary.keypoints[window.monetLabel.selected]') == keypoint


@pytest.fixture
def label_page():
    return LabelPage
